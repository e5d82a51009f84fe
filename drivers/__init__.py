"""Robot drivers: execute planned jobs on UR controllers and report how they followed the plan.

- :mod:`drivers.base`: the :class:`~drivers.base.RobotDriver` protocol, :class:`~drivers.base.RobotState` and the
  :class:`~drivers.base.DriverError` family (the robot's reason with the job's time, pose and source line);
- :mod:`drivers.ur`: :class:`~drivers.ur.URDriver` on ur_rtde (servoJ streaming of the planner's joints, or the
  job's URScript program through the script port);
- :mod:`drivers.servo`: the servoJ model the drivers assume and the targets shaped by it (the arm on the planned
  joints instead of lagging them and cutting bends);
- :mod:`drivers.modbus_io`: tool I/O through the controller's Modbus server (pymodbus);
- :mod:`drivers.sim`: :class:`~drivers.sim.SimDriver`, the simulator's motion model in-process (dry runs);
- :mod:`drivers.report`: :class:`~drivers.report.ExecutionReport`, computed from what a run recorded
  (:mod:`drivers.recording`: reduced as it goes; :mod:`drivers.plan_window`: the planned path summarized once and
  searched a window at a time; :mod:`drivers.package_log`: every RTDE data package of a program run);
- :mod:`drivers.execute`: running a job on a robot as a library (execute a job, start a simulated controller,
  the demo run): what ``planner run`` and the service's executions call.

The planning core never imports this package; the drivers read the planner's one trajectory
(``job.trajectory()``), never a second sampler.
"""
