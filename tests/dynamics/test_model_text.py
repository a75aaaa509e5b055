"""`inspect MODEL`'s text (facedyn.dynamics.model_text): every field, long lists counted, a blend's members indented."""
from facedyn.dynamics.model_text import format_model_description


def test_long_lists_are_counted_and_a_blends_members_indented():
    takes = [{"name": f"take{k}", "frames": 180, "validation": k == 7} for k in range(9)]
    member = {"kind": "removal", "training": {"takes": takes, "train_pairs": 1000}, "windows": {"skull": 10}}
    text = format_model_description({"kind": "blend", "members": [member, {"kind": "response", "samples": [1, 2, 3]}],
                                     "bands": {"edges_hz": [2.0, 4.0], "weights": [[1.0, 0.0], [0.25, 0.75], [0.5, 0.5]]}})
    lines = text.splitlines()
    assert lines[0] == "kind: blend" and lines[1] == "member 1:" and lines[2] == "  kind: removal"
    assert "  training: {takes: 9 items (take0, take1, take2, take3, ..., 1 for validation), train_pairs: 1000}" in lines
    assert "  samples: [1, 2, 3]" in lines and "member 2:" in lines
    assert lines[-1] == "bands: edges 2, 4 Hz; member 1's share per band, lowest first: 1.00, 0.25, 0.50 (member 2 the rest)"
