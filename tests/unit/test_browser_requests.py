"""What the browser driver counts as a failed request (netsetest_bench/browser.py, ``_failed_requests``), on DevTools'
events as Chromium sends them: a load that failed, or was cancelled before the page had its whole body, is a failure;
a load Chromium reports as cancelled after the page had every byte its response declared is not (the live view's
43 MB viewer under load: tests/process/test_browser.py)."""

from __future__ import annotations

from netsetest_bench.browser import _failed_requests

URL = "http://127.0.0.1:1/t/re_viewer_bg.wasm"


def _load(body: list[int], failed: dict | None, length: int | None = 100) -> list[dict]:
    """The events of one request: sent, its response (with ``length`` as Content-Length), ``body`` as chunks, and
    ``failed`` (a loadingFailed's params) or a finish."""
    headers = {} if length is None else {"Content-Length": str(length)}
    events = [
        {"method": "Network.requestWillBeSent", "params": {"requestId": "1", "request": {"url": URL}}},
        {"method": "Network.responseReceived", "params": {"requestId": "1", "response": {"status": 200, "headers": headers}}},
        *({"method": "Network.dataReceived", "params": {"requestId": "1", "dataLength": n}} for n in body),
    ]
    end = {"method": "Network.loadingFinished", "params": {"requestId": "1"}}
    return [*events, {"method": "Network.loadingFailed", "params": {"requestId": "1", **failed}} if failed else end]


ABORTED = {"errorText": "net::ERR_ABORTED", "canceled": True}


def test_a_finished_load_is_no_failure() -> None:
    assert _failed_requests(_load([60, 40], None)) == []


def test_a_load_cancelled_after_its_whole_body_is_no_failure() -> None:
    assert _failed_requests(_load([60, 40], ABORTED)) == []


def test_a_load_cancelled_short_of_its_body_is_a_failure() -> None:
    assert _failed_requests(_load([60, 39], ABORTED)) == [URL]


def test_a_load_cancelled_without_a_declared_length_is_a_failure() -> None:
    assert _failed_requests(_load([60, 40], ABORTED, length=None)) == [URL]


def test_a_load_that_failed_otherwise_is_a_failure_whatever_it_got() -> None:
    assert _failed_requests(_load([60, 40], {"errorText": "net::ERR_CONTENT_LENGTH_MISMATCH", "canceled": False})) == [URL]
    assert _failed_requests(_load([], {"errorText": "net::ERR_CONNECTION_REFUSED"})) == [URL]
