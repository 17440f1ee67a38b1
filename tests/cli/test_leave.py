"""The command ends at once when nothing is left to finish, else the usual way; its status and output are kept."""

import subprocess
import sys
import threading

import pytest

import gpr3d.cli.main as cli_main


@pytest.fixture
def exits(monkeypatch):
    calls = []

    def fake_os_exit(rc):
        calls.append(("os._exit", rc))
        raise SystemExit(rc)

    monkeypatch.setattr("os._exit", fake_os_exit)
    monkeypatch.delenv("GPR3D_FAST_EXIT", raising=False)
    return calls


def test_nothing_left_to_finish_ends_at_once(exits):
    with pytest.raises(SystemExit) as e:
        cli_main.leave(3)
    assert e.value.code == 3 and exits == [("os._exit", 3)]


def test_a_thread_still_working_is_waited_for(exits):
    stop = threading.Event()
    worker = threading.Thread(target=stop.wait)  # not a daemon: the interpreter would join it
    worker.start()
    try:
        with pytest.raises(SystemExit) as e:
            cli_main.leave(0)
        assert e.value.code == 0 and exits == []  # sys.exit: the usual teardown
    finally:
        stop.set()
        worker.join()
    daemon = threading.Thread(target=stop.wait, daemon=True)  # a daemon is not waited for by the interpreter either
    stop.clear()
    daemon.start()
    with pytest.raises(SystemExit):
        cli_main.leave(0)
    assert exits == [("os._exit", 0)]
    stop.set()


def test_the_environment_can_ask_for_the_usual_exit(exits, monkeypatch):
    monkeypatch.setenv("GPR3D_FAST_EXIT", "0")
    with pytest.raises(SystemExit) as e:
        cli_main.leave(1)
    assert e.value.code == 1 and exits == []


@pytest.mark.parametrize("argv, rc", [(["--version"], 0), (["info", "/no/such/file.DZT"], 1)])
def test_status_and_output_survive_the_fast_exit(argv, rc):
    r = subprocess.run([sys.executable, "-m", "gpr3d", *argv], capture_output=True, text=True, timeout=120)
    assert r.returncode == rc
    assert (r.stdout if rc == 0 else r.stderr).strip(), r  # printed and flushed before the process ended
