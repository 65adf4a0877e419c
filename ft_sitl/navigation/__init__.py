"""Navigation algorithms: the Navigator protocol, the registry and the navigators."""

from ft_sitl.navigation.base import GiveUp, Limits, Navigator, Observation, Task

__all__ = ["GiveUp", "Limits", "Navigator", "Observation", "Task"]
