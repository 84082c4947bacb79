"""Fixed-time traffic-light programs: what the network says, and a scenario's shift of them.

A scenario may shift a traffic light's program in time (:class:`~drivefuzz.scenario.model.SignalShift`),
so that the ego meets a yellow-to-red change at speed. The shift is written into the additional file as
a copy of the network's program under :data:`PROGRAM_ID` with ``offset`` = the network's offset + the
shift; SUMO makes the program loaded last the active one. :func:`signal_state` is the same program
computed in Python, for triage, which reads only the trace and the files.

Only ``static`` programs are shifted: an actuated program's phases depend on the traffic.
Nothing here imports libsumo.
"""

from __future__ import annotations

import functools
import xml.etree.ElementTree as ET
from typing import NamedTuple

from drivefuzz.scenario.roadmap import open_network

#: [s] below SUMO's millisecond clock: moves a time on a phase boundary into the phase that ends there
_EPS = 1e-6
#: programID of a shifted copy of a network's program in a scenario's additional file
PROGRAM_ID = "drivefuzz-shift"


class Program(NamedTuple):
    type: str
    offset: float  # [s]
    phases: tuple[tuple[float, str], ...]  # (duration [s], state), in order

    @property
    def cycle(self) -> float:
        """[s] one round of the phases."""
        return sum(d for d, _ in self.phases)


@functools.lru_cache(maxsize=16)
def programs(net_path: str) -> dict[str, Program]:
    """tls id -> the first program of the network file ``net_path``."""
    with open_network(net_path) as source:
        return _read_programs(source)


def _read_programs(source) -> dict[str, Program]:
    out: dict[str, Program] = {}
    for _ev, el in ET.iterparse(source, events=("end",)):
        if el.tag == "tlLogic":
            tid = el.get("id", "")
            if tid not in out:
                phases = tuple((float(p.get("duration", "0")), p.get("state", "")) for p in el.findall("phase"))
                out[tid] = Program(el.get("type", "static"), float(el.get("offset", "0")), phases)
            el.clear()
        elif el.tag in ("edge", "junction", "connection"):
            el.clear()
    return out


def shiftable(net_path: str, tls: str) -> Program | None:
    """The network's program of ``tls`` when it can be shifted (fixed-time, with a positive cycle)."""
    prog = programs(net_path).get(tls)
    if prog is None or prog.type != "static" or not prog.phases or prog.cycle <= 0:
        return None
    return prog


def signal_state(net_path: str, tls: str, link: int, t: float, shift: float = 0.0) -> str | None:
    """The state of link ``link`` of the fixed-time program ``tls`` at simulation time ``t`` [s], with
    the program shifted by ``shift`` [s]; None where the program is not fixed-time (the trace does not say
    what it showed). As in SUMO, a phase ending at ``t`` still shows at ``t`` (the switch is seen in the
    next step)."""
    prog = shiftable(net_path, tls)
    if prog is None:
        return None
    tc = (t - prog.offset - shift - _EPS) % prog.cycle
    for dur, state in prog.phases:
        if tc < dur:
            return state[link] if link < len(state) else None
        tc -= dur
    return None


def connection_state(net_path: str, conn, t: float, signals=()) -> str | None:
    """The state a sumolib connection's light shows at ``t`` [s], its program shifted as a scenario's ``signals``
    (:class:`drivefuzz.scenario.SignalShift`) shift it; None without a light or a fixed-time program."""
    tls = conn.getTLSID()
    if not tls or conn.getTLLinkIndex() < 0:
        return None
    shift = next((s.shift for s in signals if s.tls == tls), 0.0)
    return signal_state(net_path, tls, conn.getTLLinkIndex(), t, shift)


def phase_starts(prog: Program, link: int, state_chars: str) -> list[float]:
    """[s] program times (from the cycle start, offset not applied) at which ``link`` turns to one of
    ``state_chars`` from another state."""
    out, t = [], 0.0
    n = len(prog.phases)
    for i, (dur, state) in enumerate(prog.phases):
        prev = prog.phases[i - 1][1] if n > 1 else ""
        here = state[link] if link < len(state) else ""
        before = prev[link] if link < len(prev) else ""
        if here in state_chars and before not in state_chars:
            out.append(t)
        t += dur
    return out


def tl_logic_element(tls: str, prog: Program, shift: float) -> ET.Element:
    """``<tlLogic>`` for the additional file: ``prog`` under :data:`PROGRAM_ID`, its offset moved by ``shift``."""
    el = ET.Element("tlLogic", id=tls, programID=PROGRAM_ID, type="static", offset=repr(prog.offset + shift))
    for dur, state in prog.phases:
        ET.SubElement(el, "phase", duration=repr(dur), state=state)
    return el
