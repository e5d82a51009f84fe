"""Build of the one compiled module, planner/curves/_hermite_member.c (the rest is in pyproject.toml).

It is optional: without a C compiler the install goes on and ph_quintic uses its numpy implementation of the same
rule (the same members, a C1 spline fit about 1.8 times slower). ``-ffp-contract=off`` keeps a * b + c two
roundings, as numpy computes it, so the compiled members are numpy's to the bit where both choose alike.
"""

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext


class BuildExt(build_ext):
    def build_extensions(self) -> None:
        if self.compiler.compiler_type == "unix":
            for ext in self.extensions:
                ext.extra_compile_args = [*ext.extra_compile_args, "-ffp-contract=off"]
        super().build_extensions()


setup(
    ext_modules=[Extension("planner.curves._hermite_member", ["planner/curves/_hermite_member.c"], optional=True)],
    cmdclass={"build_ext": BuildExt},
)
