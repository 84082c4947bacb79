"""CommonRoad-style planners as drivefuzz ADS plugins (the ``commonroad`` extra)."""
