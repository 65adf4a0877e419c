"""What the moving obstacles are, as plain data: their shape names and the most a field
holds. Declared once here, in a module that loads nothing, so the simulator's movers
(``scenarios.movers``, which builds them) and the bus's movers payload (``bus.codec``,
which carries them) share the values without the bus loading the scenario code and its
mesh library."""

#: the shapes of movers, in the order of their codes in ``scenarios.movers.Movers.kind``
#: (CYLINDER, BOX, SPHERE)
SHAPES = ("person", "box", "sphere")
#: each shape's size fields (m), in the order the movers' descriptions and the bus's
#: movers payload give them: a person is an upright cylinder, a box its edge lengths
SIZE_FIELDS = {"person": ("radius_m", "height_m"), "box": ("length_m", "width_m", "height_m"),
               "sphere": ("radius_m",)}
#: the most movers one field holds (the upper bound of the ``count`` setting), and so the
#: most one movers payload carries
MAX_MOVERS = 64
