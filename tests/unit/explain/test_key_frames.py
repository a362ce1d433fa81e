"""The key frames of a rendered episode and their captions."""

from __future__ import annotations

import numpy as np

from dtd.explain.render import key_frames


def test_key_frames_are_the_start_each_segments_end_and_the_final_state():
    frames = key_frames(50, np.array([0, 17, 33, 50]), success=False)
    assert [frame for frame, _ in frames] == [0, 17, 33, 50]
    assert frames[1][1] == "segment 1 ends: sub-goal 2 set"
    assert frames[2][1] == "segment 2 ends: the goal is pursued" and frames[3][1] == "final (failure)"
    assert [frame for frame, _ in key_frames(50, None, success=True)] == [0, 25, 50]


def test_rotation_goals_give_the_captions_their_angles():
    plan = {
        "reached": [False, True],
        "angles": {
            "start_to_subgoal": [40.0, 120.0],
            "segment_end_to_subgoal": [12.0, 3.0],
            "subgoal_to_goal": [80.0, 0.0],
            "start_to_goal": 120.0,
            "final_to_goal": 3.0,
        },
    }
    captions = [caption for _, caption in key_frames(100, np.array([0, 50, 100]), True, plan)]
    assert captions == [
        "start: sub-goal 1 set\n40\N{DEGREE SIGN} from here; goal 120\N{DEGREE SIGN} away",
        "segment 1 ends: the goal is pursued\nsub-goal 1 missed, 12\N{DEGREE SIGN} off",
        "final (success)\n3\N{DEGREE SIGN} from the goal",
    ]
