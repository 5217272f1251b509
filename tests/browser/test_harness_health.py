"""The health check says why a widget model missed a state update, not only that it did."""

from __future__ import annotations

import json
from typing import Any

import pytest
from harness import wait_until

pytestmark = pytest.mark.browser

# A real failed update: the kernel tells a displayed box that its child is a model the page
# never heard of. ipywidgets looks it up for 2 s, gives up ("widget model not found"), logs
# "Could not process update msg" and drops the update.
_CELLS = [
    "import ipywidgets as w\nbox = w.HBox([w.Label('kept')])\nbox",
]
_BAD_UPDATE = """
box._send({"method": "update", "state": {"children": ["IPY_MODEL_fwbnosuchmodel"]}, "buffer_paths": []})
import json; print(json.dumps(box.model_id))
"""


def test_a_failed_state_update_is_reported_with_its_cause(open_notebook: Any) -> None:
    nb = open_notebook(_CELLS)
    nb.page.locator(".widget-label", has_text="kept").wait_for()
    box_id = nb.kernel_eval(_BAD_UPDATE)
    wait_until(
        "the page to log the failed update",
        lambda: [c for c in nb.console if "Could not process update msg" in c],
        bool,
        timeout=30,
    )
    problems = nb.health_problems()
    assert len(problems) == 1, problems
    assert box_id in problems[0] and "widget model not found" in problems[0], problems
    assert "fwbnosuchmodel" in problems[0], problems  # the comm log names the unknown model
    assert "widget model not found" in (nb.artifacts / "lost-state-updates.txt").read_text()
    story = json.loads((nb.artifacts / "lost-state-comm-log.json").read_text())
    assert story[0]["model"] == box_id and story[0]["named_never_opened"] == ["fwbnosuchmodel"], story
    assert [m[2] for m in story[0]["messages"]][-1] == "send update", story
    # the page's side: it received the box's open and its update, and nothing of the unknown model
    got = [(r[1], r[2]) for r in story[0]["page_received"]]
    assert ("comm_open", box_id) in got and ("comm_msg", box_id) in got, got
    assert all(r[2] != "fwbnosuchmodel" for r in story[0]["page_received"]), got
    assert len(story[0]["page_sessions"]) == 1 and "kernel sessions the page saw: 1" in problems[0], story
    # the check itself is what the teardown runs: leave it a clean page
    nb.console.clear()
    nb.page.evaluate("() => { window.__fwbWrappedErrors = []; }")
