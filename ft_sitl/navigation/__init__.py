"""ft_sitl.navigation"""
