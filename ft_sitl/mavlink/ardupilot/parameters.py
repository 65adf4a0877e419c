"""The parameter protocol as ArduPilot answers it (GCS_Param.cpp): the PX4 face's
:class:`~ft_sitl.mavlink.parameters.Parameters` over ArduCopter's names (:mod:`.params`),
with ArduPilot's differences as its hooks: integers C-cast into PARAM_VALUE's float with
their own type (INT8, INT16, INT32), an unknown name or a NaN/inf value ignored without an
answer. A value the declaration refuses gets ArduPilot's "Param write denied" warning, the
reason in one STATUSTEXT (name, value, range) and the unchanged value echoed: ArduPilot
itself stores an out-of-range value; ft-sitl does not fly one (docs/mavlink.md, ArduCopter
face)."""

from __future__ import annotations

import math

from pymavlink.dialects.v20 import ardupilotmega as apm

from ft_sitl.autopilot import commander as cm
from ft_sitl.autopilot.params import ParamError
from ft_sitl.mavlink.ardupilot import parm
from ft_sitl.mavlink.ardupilot.params import AP_PARAMS, ApParamSet
from ft_sitl.mavlink.parameters import Parameters

#: one STATUSTEXT's text (characters; a longer one goes out in chunks)
STATUSTEXT_LEN = 50


def refusal_text(name: str, value: float | None) -> str:
    """Why a PARAM_SET of ``value`` was refused, in one STATUSTEXT (50 characters):
    "WPNAV_SPEED: 1e+06 not in 10..2000 cm/s" (the declared range, the unit when it
    fits), or that ft-sitl's controller does not fly it (a value inside ArduCopter's range
    but outside the PX4 parameter it drives: docs/mavlink.md, ArduCopter face)."""
    spec = AP_PARAMS[name]
    if value is None:
        return f"{name}: refused"
    if spec.lo <= value <= spec.hi:
        return f"{name}: {value:g} not flown by ft-sitl"[:STATUSTEXT_LEN]
    text = f"{name}: {value:g} not in {spec.lo:g}..{spec.hi:g}"
    with_unit = f"{text} {spec.unit}" if spec.unit else text
    return (with_unit if len(with_unit) <= STATUSTEXT_LEN else text)[:STATUSTEXT_LEN]


class ArduCopterParameters(Parameters):
    """One vehicle's ArduCopter parameters on the wire."""

    @property
    def store(self) -> ApParamSet:
        return self.v.ap_params

    def value(self, name: str) -> apm.MAVLink_param_value_message:
        return apm.MAVLink_param_value_message(
            name.encode("ascii"), float(self.store[name]), AP_PARAMS[name].ptype,
            len(self.names), self.index[name])

    def decode(self, name: str, m) -> float | None:
        value = float(m.param_value) if math.isfinite(m.param_value) else None
        self._asked = value  # (what a refusal names)
        return value

    def unknown(self, name: str) -> None:
        pass  # ArduPilot: no answer, no text

    def refused(self, name: str, exc: ParamError) -> None:
        self.v.cmd.text(cm.Severity.WARNING, f"Param write denied ({name})")
        self.v.cmd.text(cm.Severity.INFO, refusal_text(name, getattr(self, "_asked", None)))

    def file(self) -> bytes:
        """The parameters as a .parm file (:mod:`.parm`, MAVProxy's layout)."""
        return parm.format_parm(self.store.items()).encode()
