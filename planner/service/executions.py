"""Robot executions (issue 14's driver layer): the seam of the routes, answering 501 until the drivers land.

``POST /v1/jobs/{id}/executions`` will run a done job on a robot the operator configured (by name; a request
never carries a host), one execution per robot at a time; ``GET /v1/executions/{id}`` its progress and report.
Only keys of the ``operator`` role may execute: a planner key gets 403 already.
"""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Depends, HTTPException, Request

from planner.service.auth import Principal

router = APIRouter(tags=["executions"])


async def _caller(request: Request) -> Principal:
    from planner.service.app import principal

    return await principal(request)


Caller = Annotated[Principal, Depends(_caller)]

NOT_YET = "robot executions are not yet available in this service (the driver layer is being added)"


def require_operator(who: Principal) -> None:
    if who.role != "operator":
        raise HTTPException(403, "running a job on a robot needs a key of the operator role")


@router.post("/jobs/{job_id}/executions", status_code=202, responses={403: {"description": "not an operator key"},
                                                                      501: {"description": "not yet available"}})
def create_execution(request: Request, job_id: str, who: Caller) -> None:
    """Run a done job on a configured robot (not yet available: 501)."""
    from planner.service.app import _service, own_job

    require_operator(who)
    own_job(_service(request), who, job_id)
    raise HTTPException(501, NOT_YET)


@router.get("/executions/{execution_id}", responses={501: {"description": "not yet available"}})
def get_execution(execution_id: str, who: Caller) -> None:
    """An execution's progress and report (not yet available: 501)."""
    raise HTTPException(501, NOT_YET)
