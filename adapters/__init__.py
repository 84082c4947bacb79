"""ADS plugins around motion planners that others wrote, each installed by an extra.

drivefuzz's own packages never import anything from here: an adapter is a plugin like any
other (entry-point group ``drivefuzz.ads``), and its third-party planner is imported only
when the plugin is loaded. ``adapters.commonroad``: CommonRoad-style planners
(``pip install -e ".[commonroad]"``).
"""
