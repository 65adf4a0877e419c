"""ft_sitl.missions"""
