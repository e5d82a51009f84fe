"""Robot tool-orientation planning: PH paths, rotation-minimizing tool frames, timing and export.

The planning core (this package) is pure computation: it never does network I/O and never imports
``drivers``, ``sim`` or the service layer.
"""

__version__ = "0.1.0"
