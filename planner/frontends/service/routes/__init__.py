"""The routes, one module per resource: jobs, exports of a job, executions on robots, and the service itself
(health, metrics, the page)."""
