"""ft_sitl.physics"""
