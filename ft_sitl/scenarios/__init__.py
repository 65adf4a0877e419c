"""ft_sitl.scenarios"""
