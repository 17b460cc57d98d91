"""Classes of defect found by the reliability campaigns, checked over every call
site of the package (and the test doubles), read as Python syntax:

- a logging call whose severity is computed (``(logger.error if x else logger.info)(...)``,
  ``getattr(logger, level)(...)``): rclpy remembers the severity of each call site and raises
  ``ValueError: Logger severity cannot be changed between calls`` the second time, which
  wedged and crashed the node;
- an rclpy ``ActionClient`` (its futures can stay pending for good: ``ros/actions.py``);
- a service, service client, action server or client, or parameter client built with
  rclpy's default QoS (10 requests kept, older ones dropped silently): a burst of goals lost
  some without an answer. Ours are built with ``interface.SERVICE_QOS`` / ``ACTION_QOS``.
"""

import ast

import pytest

from conftest import PACKAGE, REPO

FILES = sorted(PACKAGE.rglob("*.py")) + sorted((REPO / "test" / "doubles").glob("*.py"))
LEVELS = {"debug", "info", "warning", "warn", "error", "fatal"}
# constructor or method -> keyword(s) that must be given
QOS_KEYWORDS = {
    "create_service": {"qos_profile"},
    "create_client": {"qos_profile"},
    "AsyncParameterClient": {"qos_profile"},
    "ActionServer": {"goal_service_qos_profile", "result_service_qos_profile",
                     "cancel_service_qos_profile"},
    "ActionClient": {"goal_service_qos_profile", "result_service_qos_profile",
                     "cancel_service_qos_profile"},
}
QOS_KEYWORDS["RaceFreeActionClient"] = QOS_KEYWORDS["ActionClient"]


def calls():
    for path in FILES:
        tree = ast.parse(path.read_text(), str(path))
        for node in ast.walk(tree):
            if isinstance(node, ast.Call):
                yield path.relative_to(REPO), node


def _name(func):
    if isinstance(func, ast.Attribute):
        return func.attr
    if isinstance(func, ast.Name):
        return func.id
    return None


def _computed_logging(call):
    """True for a call of a logger method chosen at run time."""
    func = call.func
    if isinstance(func, ast.IfExp):
        return any(_name(branch) in LEVELS for branch in (func.body, func.orelse))
    if isinstance(func, ast.Call) and _name(func.func) == "getattr" and func.args:
        return "log" in ast.unparse(func.args[0]).lower()
    return False


def _keywords(call):
    """The keywords given, ``**ACTION_QOS`` standing for the action's QoS keywords."""
    given = {k.arg for k in call.keywords if k.arg}
    if any(k.arg is None and ast.unparse(k.value) == "ACTION_QOS" for k in call.keywords):
        given |= QOS_KEYWORDS["ActionServer"]
    return given


def test_no_logging_call_site_computes_its_severity():
    found = [f"{path}:{call.lineno}: {ast.unparse(call.func)}"
             for path, call in calls() if _computed_logging(call)]
    assert not found, found


def test_the_check_sees_the_defect_it_looks_for():
    bad = ast.parse("(logger.error if failed else logger.info)('x')").body[0].value
    also = ast.parse("getattr(self.get_logger(), level)('x')").body[0].value
    fine = ast.parse("logger.error('x')").body[0].value
    assert _computed_logging(bad) and _computed_logging(also) and not _computed_logging(fine)


def test_every_service_and_action_endpoint_has_deep_queues():
    missing = []
    for path, call in calls():
        needed = QOS_KEYWORDS.get(_name(call.func))
        if needed and not needed <= _keywords(call):
            missing.append(f"{path}:{call.lineno}: {_name(call.func)} without "
                           f"{sorted(needed - _keywords(call))}")
    assert not missing, missing


def test_every_action_client_is_race_free():
    plain = [f"{path}:{call.lineno}" for path, call in calls()
             if _name(call.func) == "ActionClient"]
    assert not plain, f"use ros.actions.RaceFreeActionClient: {plain}"


@pytest.mark.parametrize("source,ok", [
    ("ActionServer(node, T, 'a', execute_callback=f)", False),
    ("ActionServer(node, T, 'a', execute_callback=f, **ACTION_QOS)", True),
    ("node.create_service(T, 'a', f)", False),
    ("node.create_service(T, 'a', f, qos_profile=SERVICE_QOS)", True),
])
def test_the_qos_check_sees_a_default(source, ok):
    call = ast.parse(source).body[0].value
    assert (QOS_KEYWORDS[_name(call.func)] <= _keywords(call)) == ok
