"""Triage of misbehaviours into findings (attribution, signatures, shrinking, reports). Works on Trace and
Scenario values.
"""
