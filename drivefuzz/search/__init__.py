"""The search: mutation strategies and their constraints (:mod:`~drivefuzz.search.mutate`) and the feedback
that steers them (:mod:`~drivefuzz.search.quality`). Works on Scenario and Trace values; never imports libsumo.
"""
