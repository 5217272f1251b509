"""The health check says why a widget model missed a state update, not only that it did."""

from __future__ import annotations

from typing import Any

import pytest

pytestmark = pytest.mark.browser


def test_a_failed_state_update_is_reported_with_its_cause(open_notebook: Any) -> None:
    nb = open_notebook(["x = 1"])
    # what ipywidgets logs when a change handler throws during set_state: a WrappedError
    # (message + error_stack: the original exception first)
    nb.page.evaluate("""() => {
      const cause = new TypeError("cannot read properties of undefined (reading 'array')");
      const wrapped = new Error("Could not process update msg for model id: abc");
      wrapped.error_stack = [cause, wrapped];
      console.error(wrapped);
    }""")
    nb.page.wait_for_function("() => (window.__fwbWrappedErrors || []).length === 1")
    nb.console.append("error: Error: Could not process update msg for model id: abc")
    problems = nb.health_problems()
    assert len(problems) == 1 and "reading 'array'" in problems[0], problems
    assert "reading 'array'" in (nb.artifacts / "lost-state-updates.txt").read_text()
    # the check itself is what the teardown runs: leave it a clean page
    nb.console.clear()
    nb.page.evaluate("() => { window.__fwbWrappedErrors = []; }")
