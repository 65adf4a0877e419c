"""ft_sitl.mavlink"""
