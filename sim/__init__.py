"""Simulated Universal Robots controller on loopback, for tests and dry runs.

Filled in by the simulator issue; the planning core never imports this package.
"""
