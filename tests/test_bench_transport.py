"""The transport benchmark runs both transcriptions end to end (one solve each, in this process)."""
import pytest

from optplan.bench import transport


@pytest.mark.parametrize("transcription", transport.TRANSCRIPTIONS)
def test_transport_row_is_complete_and_verified(transcription):
    row = transport._one(50, 0, transcription)
    assert row["transcription"] == transcription
    assert row["ipopt_status"] == "Solve_Succeeded"
    assert row["success"], row  # verified: closed-chain residual <= 1e-6, coal clearance >= 0
    assert row["active_collision_pairs"] >= 1  # the scene's hanging box is close to the guess
    text = transport.report([{"N": 50, **row}])
    assert transcription in text and "target" in text
