"""The conditions a careful driver cannot beat, read from a scenario and its trace for the attribution
(:mod:`drivefuzz.triage.attribute`): a slippery road, fog or rain that shortens the sight, a low sun in the eyes, a
strong crosswind. Each returns a short description, or None where the condition did not hold."""

from __future__ import annotations

import numpy as np

from drivefuzz.triage.evidence import sensor_range

#: [m] a sensor range below which fog and rain count as the cause of a slow journey.
SHORT_SIGHT = 50.0
#: [m/s] a crosswind from which a lane may be lost however carefully one drives (Beaufort 5, a fresh breeze;
#: below it the car's drift is centimetres): then the careful driver's replay may settle a lane invasion.
WINDY = 8.0


def slippery(trace, f: int, window_s: float = 6.0) -> str | None:
    """Friction under an axle below 0.5 in the ``window_s`` seconds before ``f`` (a car that slid on ice may
    leave its lane, or reach what it braked for, seconds later), described; None on grippy ground."""
    k0 = max(f - int(window_s / trace.step_length), 0)
    mu = np.fmin(trace["mu_front"][k0:f + 1], trace["mu_rear"][k0:f + 1])
    slippery = np.flatnonzero(mu < 0.5)  # NaN compares False
    if not len(slippery):
        return None
    k = k0 + int(slippery[0])
    return f"friction {float(np.nanmin(mu)):.2f} under the ego from {float(trace['t'][k]):.1f} s"


def short_sight(scenario) -> str | None:
    """Fog and rain that shorten the sensors' range below :data:`SHORT_SIGHT` m (a careful driver then
    drives no faster than it can stop within what it sees), described; None in clear weather."""
    w = scenario.weather
    rng = sensor_range(w)
    if rng >= SHORT_SIGHT:
        return None
    causes = [f"{name} {value:.0f}" for name, value in (("fog", w.fog), ("rain", w.rain)) if value > 0]
    return f"{' and '.join(causes)} limit{'s' if len(causes) == 1 else ''} the sensors to {rng:.0f} m"


def dazzled(scenario, trace, k0: int, f: int) -> str | None:
    """A low sun ahead of the ego (the observation's ``sun_glare``) between frames ``k0`` and ``f``, described
    from where it began; None when the sun was never in its eyes."""
    from drivefuzz.sim.world import sun_glare

    w = scenario.weather
    heading, dist = trace["heading"], trace["tls_dist"]
    for k in range(k0, f):
        if sun_glare(w, float(heading[k])):
            return f"a low sun ahead (altitude {w.sun_altitude_deg:.1f} deg) dazzled it from {float(dist[k]):.1f} m out"
    return None


def windy(scenario) -> str | None:
    """A crosswind of at least :data:`WINDY` m/s, described; None in a breeze or calm."""
    wind = scenario.weather.wind_speed
    return f"a crosswind of {wind:.1f} m/s" if wind >= WINDY else None
