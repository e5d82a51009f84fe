"""The task layer: planning a job and executing a job on a robot are tasks of one life cycle, run by one of two
backends.

- :mod:`.lifecycle`: the kinds of task (job, execution), their states, and the one typed message a task sends
  (:class:`~.lifecycle.Progress`) and returns (:class:`~.lifecycle.Outcome`).
- :mod:`.functions`: the two task functions, :func:`~.functions.plan_job` and :func:`~.functions.execute_job`, free
  of web, database and backend.
- :mod:`.child`: the worker process that runs them (spawned; stopped by a message, killed when it must).
- :mod:`.transitions`: every change of a task's row (claim, progress and heartbeat, finish with its plan, cancel,
  recovery, the robot's lease), each one conditional statement.
- :mod:`.runner`: one task in a worker process, relayed into the store (cancellation, time limit, heartbeats).
- :mod:`.local` (the default: worker processes of the service itself, no broker) and :mod:`.celery_backend` (Celery
  workers on any number of machines, Redis as broker, the store in PostgreSQL).
"""
