"""The HTTP API's error answers can always be built and are always JSON, whatever caller
input their message or field name echoes."""

import json

import pytest

from oricf.errors import InvalidInput
from oricf.services.runtime.errors import MAX_MESSAGE
from oricf.services.runtime.http.errors import ApiError, as_api_error, error_response


def test_an_error_echoing_a_lone_surrogate_is_json() -> None:
    """A lone surrogate cannot be written as UTF-8: it is sent as its escape."""
    response = error_response(ApiError(404, "model 'gemma\ud800' is not served here",
                                       param="model\udfff", code="model_not_found"))
    assert response.status_code == 404
    error = json.loads(response.body)["error"]
    assert error["message"] == "model 'gemma\\ud800' is not served here"
    assert error["param"] == "model\\udfff" and error["code"] == "model_not_found"


@pytest.mark.parametrize("text", ["\ud800" * (2 * MAX_MESSAGE), "x\udc00" * MAX_MESSAGE])
def test_an_escaped_message_is_still_cut(text: str) -> None:
    error = error_response(as_api_error(InvalidInput(text), 100))
    message = json.loads(error.body)["error"]["message"]
    assert error.status_code == 400 and message.endswith("... (cut)")
    assert len(message) <= MAX_MESSAGE + len("... (cut)")
