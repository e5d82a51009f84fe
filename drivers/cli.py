"""Deprecated (kept for one release): ``planner run`` is :mod:`planner.frontends.cli.run`, and running a job on a
robot as a library is :mod:`drivers.execute` (``execute_job``, ``start_sim``, ``run_demo_on_sim``, ``plot_run``,
``free_loopback_host``). Importing this module warns.
"""

from planner._deprecated import moved_module

__getattr__ = moved_module(__name__, ("drivers.execute", "planner.frontends.cli.run"),
                           "use drivers.execute (execute_job, start_sim, run_demo_on_sim) and "
                           "planner.frontends.cli.run (the planner run command)")
