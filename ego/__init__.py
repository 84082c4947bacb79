"""The reference ADS of drivefuzz (entry point ``drivefuzz.ads: ego``) and the ``sumo`` ADS.

Four layers, like a real stack: :mod:`ego.sensing` -> :mod:`ego.perception` ->
:mod:`ego.planning` -> :mod:`ego.actuation`, composed in :mod:`ego.ads`.
"""
