"""The front ends, on top of every other layer: the command line (:mod:`planner.frontends.cli`, ``planner ...``) and
the REST service (:mod:`planner.frontends.service`, ``planner serve``). They import the planning core, the drivers
and the simulator; nothing below imports them (contracts in pyproject.toml, checked by the test command).
"""
