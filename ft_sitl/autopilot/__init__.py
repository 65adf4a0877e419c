"""ft_sitl.autopilot"""
