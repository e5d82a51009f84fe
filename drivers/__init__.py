"""Robot drivers: stream planned poses to a UR controller (ur_rtde) and drive tool I/O (pymodbus).

Filled in by the driver-layer issue; the planning core never imports this package.
"""
