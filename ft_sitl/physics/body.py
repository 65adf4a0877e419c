"""A quadrotor's collision body: its central body and its rotor disks, in the body frame.

The body is what touches the world (from trial protocol 5; docs/platforms.md, "Collision
body"): a box for the central body (frame plates, flight controller, battery) and one
flat cylinder per rotor, the disk its propeller sweeps, centred on the rotor hub at the
arm's end. Everything is in the body FLU frame, origin at the centre of mass, so the
vehicle's attitude poses it in the world: a vehicle yawed 45 degrees presents a different
width to a gap than an unyawed one, and a tilted one dips a rotor lower on one side.

A platform may set three dimensions (:data:`BODY_FIELDS`); what it leaves out follows the
rules below, scaled by the arm length d (the paper's d) so they hold from 0.25 kg racers
to 8 kg lifters:

* central body: ``body_size_m`` = [0.6 d, 0.6 d, 0.35 d] (length, width, height; a
  450 mm frame, d = 0.225 m, gets a 0.135 m square, 0.08 m tall body);
* rotor disks: radius = half the propeller diameter, thickness ``rotor_disk_thickness_m``
  = 0.1 d (blade sweep and hub);
* rotor plane: ``rotor_height_m`` = 0.15 d above the centre of mass (propellers sit on
  top of the motors, above the arms).

Derived here, never stored: the bounding radius (the farthest body point from the centre
of mass: the guard's broad-phase sphere), the half span (the farthest body point from the
vertical axis through the centre of mass: the footprint a navigator keeps obstacles
away by, whatever its yaw) and the half height.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ft_sitl.physics.layouts import get_layout
from ft_sitl.rotations import matrix_from_quat

#: the central body's default size, per metre of arm length [length, width, height]
BODY_SIZE_PER_ARM = (0.6, 0.6, 0.35)
#: the default rotor-disk thickness, per metre of arm length
ROTOR_THICKNESS_PER_ARM = 0.1
#: the default height of the rotor plane above the centre of mass, per metre of arm length
ROTOR_HEIGHT_PER_ARM = 0.15

#: the optional platform fields that set the body (unit, range, doc), checked by
#: :func:`ft_sitl.physics.platform.validate` like every other field
BODY_FIELDS = {
    "body_size_m": ("m", 0.005, 3.0,
                    "central body box [length, width, height] (FLU; default "
                    "[0.6, 0.6, 0.35] x arm length)"),
    "rotor_disk_thickness_m": ("m", 0.001, 0.5,
                               "thickness of each rotor's propeller disk (default 0.1 x "
                               "arm length)"),
    "rotor_height_m": ("m", -0.5, 0.5,
                       "height of the rotor plane above the centre of mass (default 0.15 x "
                       "arm length)"),
}


@dataclass(frozen=True)
class Box:
    """A box: ``center`` (body FLU, m) and full ``size`` [x, y, z] (m), body-axis aligned."""

    center: tuple[float, float, float]
    size: tuple[float, float, float]

    def reach(self) -> tuple[float, float]:
        """(farthest distance from the origin, farthest distance from the body z axis)."""
        h = [abs(c) + s / 2 for c, s in zip(self.center, self.size)]
        return math.sqrt(h[0] ** 2 + h[1] ** 2 + h[2] ** 2), math.hypot(h[0], h[1])


@dataclass(frozen=True)
class Disk:
    """A flat cylinder with its axis along body z: ``center`` (body FLU, m), ``radius`` and
    ``thickness`` (m)."""

    center: tuple[float, float, float]
    radius: float
    thickness: float

    def reach(self) -> tuple[float, float]:
        horizontal = math.hypot(self.center[0], self.center[1]) + self.radius
        return math.hypot(horizontal, abs(self.center[2]) + self.thickness / 2), horizontal


@dataclass(frozen=True)
class VehicleBody:
    """The central body and the rotor disks of one vehicle (body FLU frame)."""

    box: Box
    rotors: tuple[Disk, ...]

    @property
    def parts(self) -> tuple[Box | Disk, ...]:
        return (self.box, *self.rotors)

    @property
    def bounding_radius_m(self) -> float:
        """The farthest point of the body from the centre of mass (m)."""
        return max(p.reach()[0] for p in self.parts)

    @property
    def half_span_m(self) -> float:
        """The farthest point of the body from the vertical body axis (m): the radius of the
        upright cylinder that holds the level vehicle at any yaw."""
        return max(p.reach()[1] for p in self.parts)

    @property
    def half_height_m(self) -> float:
        """Half the height of the upright cylinder around the centre of mass that holds the
        level vehicle (m)."""
        return max(abs(self.box.center[2]) + self.box.size[2] / 2,
                   *(abs(d.center[2]) + d.thickness / 2 for d in self.rotors))

    def describe(self) -> dict:
        """The body's dimensions as plain data (``platforms show``)."""
        return {
            "body_size_m": list(self.box.size),
            "rotor_disk_radius_m": self.rotors[0].radius,
            "rotor_disk_thickness_m": self.rotors[0].thickness,
            "rotor_height_m": self.rotors[0].center[2],
            "rotor_hubs_m": [list(d.center[:2]) for d in self.rotors],
            "bounding_radius_m": self.bounding_radius_m,
            "half_span_m": self.half_span_m,
            "half_height_m": self.half_height_m,
        }


def build_body(layout: str, arm_length_m: float, prop_diameter_m: float,
               body_size_m=None, rotor_disk_thickness_m=None,
               rotor_height_m=None) -> VehicleBody:
    """The body of a platform from its geometry; ``None`` dimensions follow the defaults
    of the module docstring."""
    d = float(arm_length_m)
    size = tuple(float(v) for v in (body_size_m if body_size_m is not None
                                    else [k * d for k in BODY_SIZE_PER_ARM]))
    thick = float(rotor_disk_thickness_m if rotor_disk_thickness_m is not None
                  else ROTOR_THICKNESS_PER_ARM * d)
    height = float(rotor_height_m if rotor_height_m is not None
                   else ROTOR_HEIGHT_PER_ARM * d)
    hubs = get_layout(layout).rotor_positions(d)
    rotors = tuple(Disk((float(x), float(y), height), float(prop_diameter_m) / 2, thick)
                   for x, y, _ in hubs)
    return VehicleBody(Box((0.0, 0.0, 0.0), size), rotors)


def world_points(body: VehicleBody, position, q_world_body) -> np.ndarray:
    """The centres of the body's parts in the world frame (n_parts, 3), for plots and
    tests."""
    rot = matrix_from_quat(q_world_body)
    return np.array([np.asarray(position, float) + rot @ np.asarray(p.center, float)
                     for p in body.parts])
