"""The typed responses (planner.frontends.service.schemas): the job's summary and links round-trip through their
models unchanged (every key declared, none added), the models say their units."""

from __future__ import annotations

import pytest

from planner import PlanSettings, plan
from planner.frontends.cli.main import EXAMPLE_CLS, example_path
from planner.frontends.service.schemas import ExecutionView, JobLinks, JobSummary, JobView
from planner.frontends.service.tasks.functions import plain

DEMO = example_path(EXAMPLE_CLS)


@pytest.mark.parametrize("settings", [PlanSettings(), PlanSettings(robot="ur5e", part_frame="auto")],
                         ids=["no robot", "robot, placed"])
def test_the_summary_round_trips_through_its_model(settings):
    """What the worker stores (plain(job.summary())) is what GET /v1/jobs/{id} shows: the model declares every
    key (an undeclared one is refused) and adds none."""
    stored = plain(plan(DEMO, settings).summary())
    shown = JobSummary.model_validate(stored).model_dump(mode="json", exclude_unset=True)
    assert shown == stored
    assert list(shown) == list(stored)
    if settings.robot is not None:
        assert shown["part_frame_auto"]["option"] and shown["reachable"] in (True, False)
    with pytest.raises(ValueError, match="extra"):
        JobSummary.model_validate({**stored, "new_figure_mm": 1.0})


def test_links_keep_their_names_and_leave_out_the_exports_not_made():
    queued = {"self": "/v1/jobs/a"}
    done = {**queued, "csv": "/v1/jobs/a/trajectory?format=csv", "json": "/v1/jobs/a/trajectory?format=json",
            "plot": "/v1/jobs/a/plot.png"}
    for links in (queued, done):
        assert JobLinks.model_validate(links).model_dump(by_alias=True, exclude_unset=True) == links
    assert set(JobLinks.model_json_schema(by_alias=True)["properties"]) == {"self", "csv", "json", "plot", "script"}


def test_the_views_say_their_units():
    for model in (JobView, ExecutionView):
        assert "Units: a quantity's name ends with its unit" in (model.__doc__ or "")
    assert "SI" in JobView.model_json_schema()["description"]
