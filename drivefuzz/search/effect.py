"""What an execution would do, as a hash: two scenarios with the same effect hash execute identically.

A fuzz job (:mod:`drivefuzz.campaign.job`) keeps the effect hashes of every execution it has run, and a
population member whose hash is among them is drawn again (bounded), so that no execution is spent on a
scenario that only differs from an executed one in what the simulation never reads:

- the scenario's ``name`` (a label);
- the weather's ``cloud`` and ``puddle_density`` (kept in the model for the files' sake, read nowhere);
- the sun's azimuth and altitude while the sun cannot dazzle (:func:`drivefuzz.sim.world.sun_glare` reads
  them only for an altitude between -5 and 20 degrees): a sun at 45 degrees is the same as one at 70.

Everything else (actors, puddles, signal shifts, the ADS and its options, the RNG seed, the simulation
options) goes in as :meth:`Scenario.content_hash` has it. The hash is conservative: scenarios it tells
apart may still execute alike (two actors swapped in order), but two it calls equal execute alike.
Pure; never imports libsumo.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

#: sun altitudes [deg] strictly between these can dazzle (drivefuzz.sim.world.sun_glare)
GLARE_ALTITUDE = (-5.0, 20.0)


def effect_hash(sc) -> str:
    """Short stable hash of what decides ``sc``'s execution (see the module docstring)."""
    data = sc.model_dump(mode="json")
    data["network"] = Path(sc.network).name
    data.pop("name", None)
    w = data["weather"]
    w.pop("cloud", None)
    w.pop("puddle_density", None)
    if not GLARE_ALTITUDE[0] < w["sun_altitude_deg"] < GLARE_ALTITUDE[1]:
        w["sun_altitude_deg"] = w["sun_azimuth_deg"] = None  # no glare: where the sun stands is read nowhere
    blob = json.dumps(data, sort_keys=True, separators=(",", ":")).encode()
    return hashlib.sha256(blob).hexdigest()[:16]
