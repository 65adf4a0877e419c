"""The parameter protocol as ArduPilot answers it (GCS_Param.cpp): the PX4 face's
:class:`~ft_sitl.mavlink.parameters.Parameters` over ArduCopter's names (:mod:`.params`),
with ArduPilot's differences as its hooks: integers C-cast into PARAM_VALUE's float with
their own type (INT8, INT16, INT32), an unknown name or a NaN/inf value ignored without an
answer. A value the declaration refuses gets ArduPilot's "Param write denied" warning, the
reason (name, value, range) and the unchanged value echoed: ArduPilot itself stores an
out-of-range value; ft-sitl does not fly one (docs/mavlink.md, ArduCopter face)."""

from __future__ import annotations

import math

from pymavlink.dialects.v20 import ardupilotmega as apm

from ft_sitl.autopilot import commander as cm
from ft_sitl.autopilot.params import ParamError
from ft_sitl.mavlink.ardupilot import parm
from ft_sitl.mavlink.ardupilot.params import AP_PARAMS, ApParamSet
from ft_sitl.mavlink.parameters import Parameters


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
        return float(m.param_value) if math.isfinite(m.param_value) else None

    def unknown(self, name: str) -> None:
        pass  # ArduPilot: no answer, no text

    def refused(self, name: str, exc: ParamError) -> None:
        self.v.cmd.text(cm.Severity.WARNING, f"Param write denied ({name})")
        self.v.cmd.text(cm.Severity.INFO, str(exc))

    def file(self) -> bytes:
        """The parameters as a .parm file (:mod:`.parm`, MAVProxy's layout)."""
        return parm.format_parm(self.store.items()).encode()
