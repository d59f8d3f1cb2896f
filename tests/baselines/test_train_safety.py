"""Issue 16 items 7, 8, 10, 12: train.py never overwrites a run by accident, checkpoints are written
as
one unit, and options and saved state are validated."""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

import pytest

os.environ.setdefault("HF_HUB_OFFLINE", "1")
os.environ.setdefault("HF_DATASETS_OFFLINE", "1")

import torch  # noqa: E402

torch.set_num_threads(1)

from baselines_toy import toy_dataset  # noqa: E402
from safetensors.torch import load_file  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from handover_eval.cli import train  # noqa: E402

ACT_TINY = ["--dim-model", "16", "--n-heads", "2", "--dim-feedforward", "32"]


@pytest.fixture(scope="module")
def data_path(tmp_path_factory) -> Path:
    return toy_dataset(n=8, length=40, seed=6).save(tmp_path_factory.mktemp("data") / "toy.npz")


def bc(data_path: Path, out: Path, *extra: str) -> list[str]:
    return [
        "bc-mlp",
        "--smoke",
        "--data",
        str(data_path),
        "--out",
        str(out),
        "--no-progress",
        *extra,
    ]


def act(data_path: Path, out: Path, *extra: str) -> list[str]:
    return [
        "act",
        "--smoke",
        "--data",
        str(data_path),
        "--out",
        str(out),
        "--no-progress",
        "--steps",
        "4",
        "--eval-every",
        "2",
        *ACT_TINY,
        *extra,
    ]


def _files(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*"))
            if p.is_file() and "lerobot_dataset" not in p.parts}


def _weights(path: Path) -> dict[str, torch.Tensor]:
    return load_file(path)


def _same(a: dict, b: dict) -> bool:
    return a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)


# ---------------------------------------------------------------------- item 7
def test_a_finished_run_is_never_overwritten_without_asking(data_path, tmp_path, capsys):
    from baselines.act import ACTAgent
    from baselines.bc_mlp import BCMLPAgent

    out = tmp_path / "run"
    assert train.main(bc(data_path, out)) == 0
    before = _files(out)
    assert train.main(act(data_path, out)) == 2
    assert "holds a BC-MLP checkpoint, not ACT; pass --overwrite" in capsys.readouterr().err
    assert train.main(bc(data_path, out)) == 2
    assert (
        "already holds a BC-MLP run; pass --resume to continue it or --overwrite"
        in capsys.readouterr().err
    )
    assert _files(out) == before and BCMLPAgent.load(out).fitted
    assert train.main(act(data_path, out, "--overwrite")) == 0
    assert ACTAgent.load(out).fitted
    assert (
        json.loads((out / "config.json").read_text())["type"] == "act"
    )  # no BC-MLP file left behind
    assert train.main(bc(data_path, out, "--resume")) == 2
    assert "holds a ACT checkpoint, not BC-MLP" in capsys.readouterr().err


def test_a_folder_of_other_files_is_refused_even_with_overwrite(data_path, tmp_path, capsys):
    out = tmp_path / "mine"
    out.mkdir()
    (out / "notes.txt").write_text("keep")
    for extra in ((), ("--overwrite",)):
        assert train.main(bc(data_path, out, *extra)) == 2
        assert (
            "is not empty and holds no checkpoint of this project (notes.txt)"
            in capsys.readouterr().err
        )
    assert [p.name for p in out.iterdir()] == ["notes.txt"]


# ---------------------------------------------------------------------- item 8
class _Interrupt:
    """Raise KeyboardInterrupt on the n-th call of ``cls.state_dict`` (the optimizer save)."""

    def __init__(self, monkeypatch, cls, n: int) -> None:
        self.real, self.calls, self.n = cls.state_dict, 0, n
        monkeypatch.setattr(cls, "state_dict", self)

    def __get__(self, obj, objtype=None):
        def call(*args, **kwargs):
            self.calls += 1
            if self.calls == self.n:
                raise KeyboardInterrupt
            return self.real(obj, *args, **kwargs)
        return call


@pytest.mark.parametrize("method", ["bc-mlp", "act"])
def test_a_kill_between_checkpoint_files_resumes_exactly(data_path, tmp_path, monkeypatch, method):
    """Killed after the weights but before the optimizer and state.json of a checkpoint, --resume
    used to continue from mixed epochs; now it continues from the last whole checkpoint."""
    argv = bc if method == "bc-mlp" else act
    opt_cls = torch.optim.Adam if method == "bc-mlp" else torch.optim.AdamW
    assert train.main(argv(data_path, tmp_path / "straight")) == 0
    with monkeypatch.context() as m:
        interrupt = _Interrupt(m, opt_cls, 2)  # the second checkpoint's optimizer save
        assert train.main(argv(data_path, tmp_path / "killed")) == 130
        assert interrupt.calls == 2
    state = json.loads((tmp_path / "killed" / "training_state" / "state.json").read_text())
    assert state.get("epoch", state.get("step")) == (
        1 if method == "bc-mlp" else 2
    )  # the first checkpoint
    assert not (tmp_path / "killed" / ".staging").exists()
    assert train.main(argv(data_path, tmp_path / "killed", "--resume")) == 0
    for name in ("model.safetensors", "training_state/last.safetensors"):
        assert _same(
            _weights(tmp_path / "straight" / name), _weights(tmp_path / "killed" / name)
        ), name


def test_an_interrupted_commit_is_finished_by_the_writers_recovery(tmp_path):
    from baselines.checkpoint_io import recover, staged_write

    out = tmp_path / "ckpt"
    with staged_write(out) as stage:
        (stage / "a.json").write_text("1")
        (stage / "sub").mkdir()
        (stage / "sub" / "b.json").write_text("1")
    # a second write killed after its commit record, with one file already moved
    stage = out / ".staging"
    (stage / "sub").mkdir(parents=True)
    (stage / "sub" / "b.json").write_text("2")
    (stage / "COMMIT.json").write_text(json.dumps({"files": ["a.json", "sub/b.json"]}))
    (out / "a.json").write_text("2")
    recover(out)
    assert (out / "a.json").read_text() == (out / "sub" / "b.json").read_text() == "2"
    assert not stage.exists()
    (stage / "sub").mkdir(parents=True)  # killed before its commit record: discarded
    (stage / "sub" / "b.json").write_text("3")
    recover(out)
    assert (out / "sub" / "b.json").read_text() == "2" and not stage.exists()


@pytest.mark.parametrize("damage", ["state.json", "last.safetensors", "optimizer_state.safetensors",
                                    "optimizer_param_groups.json"])
def test_a_half_written_file_is_a_one_line_error(data_path, tmp_path, capsys, damage):
    out = tmp_path / "run"
    assert train.main(bc(data_path, out)) == 0
    path = out / "training_state" / damage
    path.write_bytes(path.read_bytes()[: len(path.read_bytes()) // 2])
    capsys.readouterr()
    assert train.main(bc(data_path, out, "--resume")) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("train.py: error: ") and str(path) in err and "\n" not in err, err


# ---------------------------------------------------------------------- item 12
@pytest.mark.parametrize("option, value", [("--lr", "0"), ("--batch-size", "0"), ("--lr", "-1e-3"),
                                           ("--epochs", "0"), ("--val-fraction", "1")])
def test_zero_or_negative_options_are_errors_not_defaults(
    data_path, tmp_path, capsys, option, value
):
    with pytest.raises(SystemExit, match="^2$") as exc:
        train.main(bc(data_path, tmp_path / "run", f"{option}={value}"))
    assert exc.value.code == 2
    assert f"argument {option}: must be" in capsys.readouterr().err
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize(
    "device", ["bogus", "cuda:7"] if not torch.cuda.is_available() else ["bogus"]
)
def test_an_unusable_device_is_a_one_line_error(data_path, tmp_path, capsys, device):
    assert train.main(bc(data_path, tmp_path / "run", "--device", device)) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"train.py: error: --device {device!r}: not") and "\n" not in err, err


def test_a_tampered_state_json_is_refused(data_path, tmp_path, capsys):
    out = tmp_path / "run"
    assert train.main(bc(data_path, out)) == 0
    path = out / "training_state" / "state.json"
    state = json.loads(path.read_text())
    path.write_text(json.dumps({**state, "epoch": -100}))
    assert train.main(bc(data_path, out, "--resume")) == 2
    assert "inconsistent training state: epoch -100 is negative" in capsys.readouterr().err


def test_a_finished_bc_mlp_run_is_extended_by_resume_with_more_epochs(data_path, tmp_path):
    assert train.main(bc(data_path, tmp_path / "five", "--epochs", "5", "--patience", "50")) == 0
    assert train.main(bc(data_path, tmp_path / "three", "--epochs", "3", "--patience", "50")) == 0
    assert (
        train.main(
            bc(data_path, tmp_path / "three", "--epochs", "5", "--patience", "50", "--resume")
        )
        == 0
    )
    state = json.loads((tmp_path / "three" / "training_state" / "state.json").read_text())
    assert state["epoch"] == 5 and len(state["val_loss"]) == 5
    for name in ("model.safetensors", "training_state/last.safetensors"):
        assert _same(_weights(tmp_path / "five" / name), _weights(tmp_path / "three" / name)), name
