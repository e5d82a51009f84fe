"""Schemathesis over the service's OpenAPI schema (a real uvicorn on 127.0.0.1): no generated request, valid or
not, gets a 5xx. Derandomized and bounded (a few dozen examples per operation)."""

from __future__ import annotations

import schemathesis
from hypothesis import HealthCheck, given, settings
from schemathesis.checks import not_a_server_error

from tests.test_service_server import ServiceProcess


def test_no_generated_request_gets_a_server_error(tmp_path):
    s = ServiceProcess(tmp_path, workers=1, env={"PLANNER_MAX_WAYPOINTS": "2000", "PLANNER_JOB_TIMEOUT": "20"}).start()
    try:
        schema = schemathesis.openapi.from_url(s.url + "/openapi.json")
        operations = [result.ok() for result in schema.get_all_operations()]
        assert len(operations) >= 12
        seen: dict[str, set[int]] = {}
        for op in operations:
            @given(case=op.as_strategy())
            @settings(max_examples=25, deadline=None, derandomize=True, database=None,
                      suppress_health_check=list(HealthCheck))
            def run(case):
                response = case.call(timeout=60)
                seen.setdefault(case.operation.label, set()).add(response.status_code)
                case.validate_response(response, checks=[not_a_server_error])

            run()
    finally:
        assert s.stop() == 0, s.log.read_text()
    assert all(code < 500 for codes in seen.values() for code in codes), seen
    assert 422 in seen["POST /v1/jobs"] and 200 in seen["GET /v1/jobs"], seen
