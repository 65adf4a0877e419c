"""ft_sitl.bus"""
