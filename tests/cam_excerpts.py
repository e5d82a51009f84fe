"""Verbatim excerpts of the three real CAM files of shared/data, kept in ``tests/data`` for the default suite.

Each excerpt is a few line ranges of one whole file, copied byte for byte and joined in file order (UTF-8 BOM,
trailing spaces and LF line ends kept); ``tests/data/SOURCES.md`` lists the ranges, the sources and the licences.
The ranges are cut so that the excerpt reads like the whole file at every line it keeps: each range after the
first starts at a rapid (CLSF, APT: the ``RAPID`` record, or the operation's tool/frame records before it) or at
an operation start that restates the machine state (G-code: ``G53`` retract, rotary angles, ``G234``/``G254``),
and the modal tool axis and feed it inherits across the join are the ones it had in the whole file. So a reader
gives each kept motion record the same point, tool axis, feed and rapid flag as in the whole file
(``test_cam_excerpts.py`` checks this against shared/data when it is present, as a slow test).

``NX_HEAD`` (lines 1-100 of the NX CLSF job, the first 100 lines of its excerpt): its first pass (lines 14-53) is
a 90-degree linearised arc of radius 16 mm (13 chords, sagitta 0.029 mm), a straight run of 24 mm chords, and
another 90-degree arc; RAPID records on lines 10, 13, 55 and 97 each make the next GOTO a rapid. Line 7 keeps its
trailing space.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from tests.conftest import EXCERPT_DATA


@dataclass(frozen=True)
class Excerpt:
    """``ranges`` (1-based, inclusive line numbers of ``source``, in file order) copied into ``tests/data/name``."""

    name: str
    source: str
    ranges: tuple[tuple[int, int], ...]

    @property
    def path(self):
        return EXCERPT_DATA / self.name

    @cached_property
    def original_lines(self) -> np.ndarray:
        """(n,) int: the whole file's line number of each excerpt line (excerpt line k is entry k - 1)."""
        return np.concatenate([np.arange(a, b + 1) for a, b in self.ranges])

    def original_line(self, line):
        """The whole file's line number(s) of excerpt line(s) ``line`` (1-based; int or int array)."""
        return self.original_lines[np.asarray(line) - 1]

    def lines(self) -> dict[int, str]:
        """The excerpt's lines keyed by the whole file's line numbers (without line ends, BOM kept)."""
        text = self._lines(keepends=False)
        assert len(text) == len(self.original_lines), f"{self.path}: line count differs from its ranges"
        return dict(zip(self.original_lines.tolist(), text, strict=True))

    def head(self, n: int) -> str:
        """The first ``n`` lines of the excerpt, verbatim (the whole file's lines 1..n when n <= ranges[0][1])."""
        if self.ranges[0][0] != 1 or n > self.ranges[0][1]:
            raise ValueError(f"{self.name}: lines 1-{n} are not one range of the excerpt")
        return "".join(self._lines(keepends=True)[:n])

    def _lines(self, keepends: bool) -> list[str]:
        # split at LF only (str.splitlines would also split at form feeds and other separators)
        text = self.path.read_text(encoding="utf-8")
        lines = text.split("\n")
        last = lines.pop()  # "" when the file ends with a line end
        if keepends:
            lines = [ln + "\n" for ln in lines]
        return lines + ([last] if last else [])


#: Siemens NX CLSF, variable-contour job (mm, modal tool axes, 1 FEDRAT, END-OF-PATH): the head with its first
#: 7 passes; a pass whose rapid carries its axis; the pass of largest tilt (89.04 deg at line 7269); passes 225-226
#: (line 7540); passes 757-768 (lines 20179-20416, a reconfiguration on a UR5e); the irregular end of the job
#: (lines 20753-20823: rapids with axes, 0.02 mm steps); the last rapid and END-OF-PATH.
NX = Excerpt(
    "nx_clsf_ust_a2_excerpt.cls",
    "nx_clsf_variable_contour_ust_a2.cls",
    ((1, 305), (4792, 4851), (7247, 7307), (7538, 7653), (20179, 20416), (20753, 20823), (22237, 22242)),
)
#: The same NX job's passes whose tool axis turns one way and then back, each a protective stop of issue 29 in
#: program mode: pass 116 of the whole job (lines 4703-4727; 82 deg one way up to line 4711, back by 1.3 deg at line
#: 4712, after pass 115 from line 4678) and pass 124 (lines 4794-4851; back by 5.0 deg within the 0.081 mm step from
#: line 4833 to 4834). The header up to the only FEDRAT (line 16, the axis then 0,0,-1 as at line 4677), the rapid
#: of line 4677 to the rapid after pass 116 (line 4730), and the NX excerpt's range of pass 124.
NX_AXIS_REVERSAL = Excerpt(
    "nx_clsf_ust_a2_axis_reversal.cls",
    "nx_clsf_variable_contour_ust_a2.cls",
    ((1, 16), (4677, 4730), (4792, 4851)),
)
#: SOLIDWORKS CAM APT, 3+2 job (mm, CIRCLE records, CUTCOM, CSYS frames, tool changes, FINI).
SW = Excerpt(
    "solidworks_cam_apt_boss_excerpt.apt",
    "solidworks_cam_apt_boss_3plus2.apt",
    ((1, 53), (3726, 3755), (4838, 4909), (5542, 5631), (12360, 12427)),
)
#: NX 2022 G-code for a Haas UMC-750 (inch, BOM and listing header, G02/G03, 3+2 under G254, 5-axis under G234).
HAAS = Excerpt(
    "nx2022_haas_umc750_excerpt.txt",
    "nx2022_haas_umc750_5axis_gcode.txt",
    ((1, 76), (1385, 1659), (15501, 15655), (15961, 16121)),
)
#: The NX CLSF job again: the pass of lines 17682-17698, whose JSON export moved by one ulp when the PH quintic
#: member's axis was computed in another order (issue 25), between passes that carry the modal tool axis to it and
#: back to the last rapid's.
NX_ROUNDING = Excerpt(
    "nx_clsf_ust_a2_rounding_excerpt.cls",
    "nx_clsf_variable_contour_ust_a2.cls",
    ((1, 16), (4467, 4510), (7832, 7886), (10721, 10771), (17681, 17743), (17872, 17929), (20753, 20769),
     (22237, 22242)),
)
EXCERPTS = {e.name: e for e in (NX, NX_AXIS_REVERSAL, SW, HAAS, NX_ROUNDING)}

NX_HEAD = NX.head(100)
