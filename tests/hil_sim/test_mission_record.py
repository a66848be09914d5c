"""`ramp sim mission --record FILE.mcap`: the autonomy's view and the simulator's truth in one
MCAP file, read back with the `mcap` reader (SPEC 8): every channel present with its schema,
every message valid against it, the poses at 10 Hz, the estimate close to the truth, the
state changes in order, scans and the map. A 40 s run: about 2 s of wall time."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import jsonschema
import pytest
from mcap.reader import make_reader

from ramp.cli import main

pytestmark = pytest.mark.timeout(120)

TOPICS = {
    "/mission/state": "ramp.MissionState", "/pose/true": "foxglove.PoseInFrame",
    "/pose/estimated": "foxglove.PoseInFrame", "/mission/numbers": "ramp.MissionNumbers",
    "/lidar/scan": "foxglove.LaserScan", "/map": "foxglove.SceneUpdate"}


def test_a_recorded_mission_holds_the_autonomy_view_and_the_truth_valid_in_foxglove_schemas(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "run.mcap"
    main(["sim", "mission", "--duration", "40", "--record", str(path), "--json"])
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert summary["record"] == str(path)
    messages: dict[str, list[tuple[int, dict[str, Any]]]] = {t: [] for t in TOPICS}
    with path.open("rb") as f:
        reader = make_reader(f)
        channels = {ch.topic: ch for ch in reader.get_summary().channels.values()}
        schemas = reader.get_summary().schemas
        for topic, name in TOPICS.items():
            schema = schemas[channels[topic].schema_id]
            assert (schema.name, schema.encoding, channels[topic].message_encoding) == (
                name, "jsonschema", "json")
            jsonschema.Draft202012Validator.check_schema(json.loads(schema.data))
        validators = {t: jsonschema.Draft202012Validator(
            json.loads(schemas[channels[t].schema_id].data)) for t in TOPICS}
        for _schema, channel, message in reader.iter_messages(topics=list(TOPICS),
                                                              log_time_order=True):
            payload = json.loads(message.data)
            validators[channel.topic].validate(payload)
            messages[channel.topic].append((message.log_time, payload))

    states = [p["state"] for _, p in messages["/mission/state"]]
    assert states[:3] == ["acquire_control", "initial_localization", "prepare_for_scan"]
    fixed_at = messages["/mission/state"][2][0]  # the first localization
    truth = dict(messages["/pose/true"])
    steps = {b - a for a, b in zip(truth, list(truth)[1:], strict=False)}
    assert steps == {100_000_000}  # 10 Hz of simulated time
    assert 390 <= len(truth) <= 460  # 40 s and the grace after it
    estimated = messages["/pose/estimated"]
    assert estimated and estimated[0][0] >= fixed_at
    for stamp, est in estimated:  # the estimate, where the truth was at the same instant
        e, t = est["pose"]["position"], truth[stamp]["pose"]["position"]
        assert abs(e["x"] - t["x"]) < 0.15 and abs(e["y"] - t["y"]) < 0.15, stamp
    numbers = [p for _, p in messages["/mission/numbers"]]
    assert len(numbers) == len(truth)
    assert {"pose_confidence", "bin_kg", "true_bin_kg", "delivered_kg", "true_delivered_kg",
            "lift", "true_lift", "localization_losses"} <= set(numbers[-1])
    assert numbers[-1]["pose_confidence"] > 0.5
    scans = [p for _, p in messages["/lidar/scan"]]
    assert scans and all(len(s["ranges"]) == 1081 and s["frame_id"] == "arena" for s in scans)
    first_map = messages["/map"][0][1]["entities"][0]
    assert len(first_map["lines"][0]["points"]) == 5  # the walls, from the start
