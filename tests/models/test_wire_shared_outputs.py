"""Where an answer's outputs are: on the wire, or in shared memory as ORICF's server says
(the region named in the output's parameters, no raw entry) or as Triton answers (nothing
named, an empty raw entry kept), the latter read where the request put them."""

from __future__ import annotations

import numpy as np

from oricf.models.shared_memory import BYTE_SIZE, REGION, SharedMemoryRef
from oricf.models.wire import response_outputs, shared_outputs
from oricf.oip import open_inference_grpc_pb2 as oip

SCORES = np.arange(6, dtype=np.float32).reshape(1, 6)
ASKED = {"output": SharedMemoryRef("slot", 64, 4096)}


def answer(*, named: bool, empty_entry: bool) -> oip.ModelInferResponse:
    """An answer with `output` in shared memory and `scores` on the wire."""
    response = oip.ModelInferResponse(model_name="m")
    placed = response.outputs.add(name="output", datatype="FP32", shape=[1, 3549, 85])
    if named:
        placed.parameters[REGION].string_param = "slot"
        placed.parameters[BYTE_SIZE].int64_param = 4096
    response.outputs.add(name="scores", datatype="FP32", shape=[1, 6])
    if empty_entry:
        response.raw_output_contents.append(b"")
    response.raw_output_contents.append(SCORES.tobytes())
    return response


def test_oricfs_answer_names_the_region_itself() -> None:
    response = answer(named=True, empty_entry=False)
    np.testing.assert_array_equal(response_outputs(response)["scores"], SCORES)
    assert list(response_outputs(response)) == ["scores"]
    assert shared_outputs(response)["output"][2] == SharedMemoryRef("slot", 0, 4096)


def test_tritons_answer_is_read_where_the_request_put_the_output() -> None:
    response = answer(named=False, empty_entry=True)
    outputs = response_outputs(response, ASKED)
    assert list(outputs) == ["scores"]
    np.testing.assert_array_equal(outputs["scores"], SCORES)
    assert shared_outputs(response, ASKED) == {"output": ("FP32", [1, 3549, 85],
                                                          ASKED["output"])}
