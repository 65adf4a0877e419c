"""ft-sitl's pytest plugin: simulated PX4 vehicles for a user's MAVSDK/pymavlink tests.

Registered as the ``pytest11`` entry point ``ft_sitl`` (module :mod:`ft_sitl_pytest.plugin`),
so installing ft-sitl makes its fixtures available to every pytest run of the
environment; docs/testing.md is the guide.

Why a package beside ``ft_sitl`` and not inside it: pytest imports every ``pytest11``
plugin of the environment at start-up, whether a test uses it or not, and ``import
ft_sitl`` pins the numeric libraries' settings in ``os.environ`` and loads numba. This
package imports only the standard library and pytest at start-up; the vehicles run in
``ft-sitl sitl`` processes of their own, and pymavlink and matplotlib are loaded only when a
vehicle is served or a failed flight is plotted.
"""
