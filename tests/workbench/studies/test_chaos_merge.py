"""Merging a chaos map's shards (``studies/chaos_map.merge_shards``, ``ddvp chaos --merge``)
refuses by name every set of parts that are not one job's whole parts (issue 45): a stray folder
named like a shard, a shard past the split, two parts holding the same cells, a part with a
missing or misshapen array, a cell called a success with a non-finite figure, shards of a scene
file edited between them. Parts are written through the same manifest as the command's, so
each damage reaches the merge's own checks (a torn file is the manifest's to refuse). Random
parts (hypothesis) are merged or refused, never merged wrong."""

import shutil

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from ddvp_nlp.cli import main as ddvp
from ddvp_nlp.errors import InputError
from ddvp_nlp.io.atomic import output_folder
from ddvp_nlp.io.chaos_files import arrays_writer
from ddvp_nlp.studies.chaos_map import KEYS, merge_shards

SETTINGS = {"scene": "s", "scene_digest": "d", "energy": 0.125}


def write_part(folder, arrays, settings=SETTINGS):
    folder.parent.mkdir(parents=True, exist_ok=True)
    with output_folder(folder) as out:
        out.commit({"part.npz": arrays_writer(arrays)}, {"settings": settings})


def part(status, values=None):
    status = np.asarray(status)
    values = values if values is not None else np.where(status == "success", 1.0, np.nan)
    return {"status": status, **{key: np.array(values, dtype=float) for key in KEYS}}


def split(cells: int, count: int, k: int) -> list[str]:
    """The statuses of shard ``k`` of ``count`` over ``cells`` cells, as a job writes them:
    its own cells run, the others ``other_shard``; cell 0 off the surface in every part."""
    return ["not_run" if i == 0 else "success" if i % count == k - 1 else "other_shard"
            for i in range(cells)]


def test_whole_parts_of_one_job_merge(tmp_path):
    for k in (1, 2, 3):
        write_part(tmp_path / f"shard-{k}-of-3", part(split(10, 3, k)))
    merged, parts = merge_shards(tmp_path)
    assert sorted(parts) == ["shard-1-of-3", "shard-2-of-3", "shard-3-of-3"]
    assert list(merged["status"]) == ["not_run", *["success"] * 9]


@pytest.mark.parametrize("damage, message", [
    ("stray", "'shard-1-of-3.bak' is not a shard folder"),
    ("old", "'shard-old-of-x' is not a shard folder"),
    ("beyond", "shard-4-of-3 is past the split's 3 shards"),
    ("twice", "both hold 3 cells"),
    ("missing array", "shard-2-of-3's part has no 'megno' array"),
    ("short status", "shard-2-of-3's 'status' has shape (7,), not (10,)"),
    ("nan megno", "shard-2-of-3 calls 1 cells a success with megno = nan"),
    ("inf steps", "shard-2-of-3 calls 1 cells a success with steps = inf"),
    ("other scene", "shard-2-of-3 was run with other settings"),
])
def test_parts_that_do_not_belong_are_refused_by_name(tmp_path, damage, message):
    for k in (1, 3):
        write_part(tmp_path / f"shard-{k}-of-3", part(split(10, 3, k)))
    second = part(split(10, 3, 2))
    if damage == "stray":
        shutil.copytree(tmp_path / "shard-1-of-3", tmp_path / "shard-1-of-3.bak")
    elif damage == "old":
        (tmp_path / "shard-old-of-x").mkdir()
    elif damage == "beyond":
        shutil.copytree(tmp_path / "shard-1-of-3", tmp_path / "shard-4-of-3")
    elif damage == "twice":
        second = part(split(10, 3, 1))
    elif damage == "missing array":
        del second["megno"]
    elif damage == "short status":
        second["status"] = second["status"][:7]
    elif damage == "nan megno":
        second["megno"][4] = np.nan
    elif damage == "inf steps":
        second["steps"][7] = np.inf
    write_part(tmp_path / "shard-2-of-3", second,
               {**SETTINGS, "scene_digest": "e"} if damage == "other scene" else SETTINGS)
    with pytest.raises(InputError, match="^folder ") as refused:  # its field; no flag
        merge_shards(tmp_path)
    assert message in str(refused.value)


@settings(max_examples=40, derandomize=True, deadline=None, database=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.integers(1, 4), st.integers(1, 9), st.data())
def test_random_parts_are_merged_right_or_refused(tmp_path_factory, count, cells, data):
    """Parts drawn at random (each cell's status in each part, NaN or finite figures): the
    merge either refuses with an InputError or returns, for every cell, the one part that ran
    it, with finite figures wherever it says success, and no cell left to another shard."""
    root = tmp_path_factory.mktemp("parts")
    status = st.sampled_from(["success", "other_shard", "not_run", "newton_failed"])
    value = st.sampled_from([1.0, -2.5, np.nan])
    drawn = []
    for k in range(1, count + 1):
        statuses = data.draw(st.lists(status, min_size=cells, max_size=cells))
        values = data.draw(st.lists(value, min_size=cells, max_size=cells))
        drawn.append((statuses, values))
        write_part(root / f"shard-{k}-of-{count}", part(statuses, values))
    try:
        merged, _ = merge_shards(root)
    except InputError as refused:
        assert str(refused).startswith("folder ")
        return
    for cell in range(cells):
        ran = [s[cell] for s, _ in drawn if s[cell] not in ("other_shard", "not_run")]
        assert len(ran) <= 1
        assert merged["status"][cell] == (ran[0] if ran else "not_run")
        if merged["status"][cell] == "success":
            assert np.isfinite(merged["megno"][cell])


def test_shards_of_a_scene_edited_between_them_are_not_merged(tmp_path, capsys):
    """The same file name, its potential changed between shard 1 and shard 2: refused by
    its settings (the scene's hash), exit 2, no traceback."""
    scene = tmp_path / "cell.py"
    body = ("from ddvp_nlp import Scene\ndef H(q, p, t):\n    return (p[0]**2 + p[1]**2)/2 + "
            "(q[0]**2 + q[1]**2)/2 + {c}*q[0]**2*q[1]\n"
            "scene = Scene(H, n=2, q0=[0.1, 0.0], p0=[0.0, 0.4], tau0=0.05, t_end=5)\n")
    for k, c in ((1, "1.0"), (2, "0.9")):
        scene.write_text(body.format(c=c))
        assert ddvp(["chaos", str(scene), "--energy", "0.1", "--grid", "q2=-0.2:0.2:2,p2=0:0.1:2",
                     "--t-end", "2", "--out", str(tmp_path / "parts"), "--workers", "1",
                     "--no-progress", "--no-plot", "--shard", f"{k}/2"]) == 0
    capsys.readouterr()
    assert ddvp(["chaos", "--merge", str(tmp_path / "parts"), "--no-plot"]) == 2
    err = capsys.readouterr().err
    assert "shard-2-of-2 was run with other settings" in err and "Traceback" not in err
