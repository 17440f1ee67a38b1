"""gpr3d's weight files: float16 state dicts, and every wrong file named in one line before a model is built."""

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from gpr3d.core.errors import FormatError  # noqa: E402
from gpr3d.io.weights import half_state_dict, read_weights_file  # noqa: E402


class _Net(torch.nn.Module):
    def __init__(self):
        super().__init__()
        self.lin = torch.nn.Linear(3, 2)
        self.register_buffer("count", torch.tensor([7, 9], dtype=torch.int64))


def test_half_state_dict_rounds_floats_to_float16_and_keeps_integers():
    torch.manual_seed(0)
    net = _Net()
    with torch.no_grad():
        net.lin.weight.copy_(torch.tensor([[0.1, 1 / 3, 1e-5], [65504.0, -2.5, 1.0009765625]]))
    sd = half_state_dict(net)
    assert set(sd) == {"lin.weight", "lin.bias", "count"}
    w = sd["lin.weight"]
    assert w.dtype == torch.float16 and not w.requires_grad and w.device.type == "cpu"
    np.testing.assert_array_equal(w.numpy(), np.array([[0.1, 1 / 3, 1e-5], [65504.0, -2.5, 1.0009765625]],
                                                       np.float16))
    assert sd["lin.bias"].dtype == torch.float16
    np.testing.assert_array_equal(sd["lin.bias"].numpy(), net.lin.bias.detach().numpy().astype(np.float16))
    assert sd["count"].dtype == torch.int64 and sd["count"].tolist() == [7, 9]
    assert net.lin.weight.dtype == torch.float32  # the model itself is left as it was


def _save(tmp_path, obj, name="w.pt"):
    p = tmp_path / name
    torch.save(obj, p)
    return p


def test_a_good_file_is_read_whole(tmp_path):
    obj = {"format": "gpr3d.detector", "version": 1, "state_dict": {"a": torch.ones(2)}, "meta": {"n": 3}}
    got = read_weights_file(_save(tmp_path, obj), "gpr3d.detector", "detector")
    assert set(got) == {"format", "version", "state_dict", "meta"} and got["meta"] == {"n": 3}
    assert torch.equal(got["state_dict"]["a"], torch.ones(2))


class Opaque:  # a class torch's weights_only loader will not build
    pass


@pytest.mark.parametrize("content, message", [
    (None, "w.pt: no such DepthNet weights file"),
    (b"not a torch file at all", "w.pt: not a readable weights file (UnpicklingError: "),
    ({"format": "gpr3d.detector", "version": 1}, "w.pt: not a gpr3d DepthNet weights file"),
    ({"version": 1}, "w.pt: not a gpr3d DepthNet weights file"),
    ([1, 2, 3], "w.pt: not a gpr3d DepthNet weights file"),
    ({"format": "gpr3d.depthnet", "version": 2}, "w.pt: DepthNet weights version 2 is not supported (expected 1)"),
    ({"format": "gpr3d.depthnet"}, "w.pt: DepthNet weights version None is not supported (expected 1)"),
    ({"format": "gpr3d.depthnet", "version": "1"},
     "w.pt: DepthNet weights version '1' is not supported (expected 1)"),
])
def test_a_wrong_file_is_named_in_one_line(tmp_path, content, message):
    p = tmp_path / "w.pt"
    if isinstance(content, bytes):
        p.write_bytes(content)
    elif content is not None:
        torch.save(content, p)
    with pytest.raises(FormatError) as err:
        read_weights_file(p, "gpr3d.depthnet", "DepthNet")
    assert str(err.value).startswith(message) and "\n" not in str(err.value)
    assert err.value.path == str(p)


def test_a_pickled_object_is_refused_not_run_and_the_reason_is_cut_to_one_short_line(tmp_path):
    p = tmp_path / "w.pt"
    torch.save({"format": "gpr3d.depthnet", "version": 1, "extra": Opaque()}, p)  # only weights_only=False reads it
    with pytest.raises(FormatError) as err:
        read_weights_file(p, "gpr3d.depthnet", "DepthNet")
    msg = str(err.value)
    head = "w.pt: not a readable weights file (UnpicklingError: "
    assert msg.startswith(head + "Weights only load failed") and msg.endswith(")") and "\n" not in msg
    assert len(msg) == len(head) + 120 + 1  # torch's first line, cut to 120 characters


def test_a_folder_is_not_a_weights_file(tmp_path):
    (tmp_path / "w.pt").mkdir()
    with pytest.raises(FormatError, match="^w.pt: no such detector weights file$"):
        read_weights_file(tmp_path / "w.pt", "gpr3d.detector", "detector")


def test_a_reason_without_words_is_still_one_line(tmp_path, monkeypatch):
    p = _save(tmp_path, {"format": "gpr3d.depthnet", "version": 1})

    def fail(*a, **k):
        raise ValueError()

    monkeypatch.setattr(torch, "load", fail)
    with pytest.raises(FormatError) as err:
        read_weights_file(p, "gpr3d.depthnet", "DepthNet")
    assert str(err.value) == "w.pt: not a readable weights file (ValueError: )"
