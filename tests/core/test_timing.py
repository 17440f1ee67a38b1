"""gpr3d.core.timing: stages timed on a clock that the test holds, so every second is known in advance."""

import subprocess
import sys

import pytest

from gpr3d.core.timing import StageTimes, collect, format_table, process_age_s, stage


class Clock:
    """Readings from a list: each call returns the next."""

    def __init__(self, *readings):
        self.readings = list(readings)

    def __call__(self):
        return self.readings.pop(0)


def test_nested_stages_count_their_own_time_and_the_rows_add_up_to_the_wall():
    # reads: collect start 0; outer in 1; inner in 3; inner out 7; outer out 10; again outer in 12, out 13; end 20
    clock = Clock(0.0, 1.0, 3.0, 7.0, 10.0, 12.0, 13.0, 20.0)
    with collect(compile_times=False, clock=clock) as t:
        with stage("outer"):
            with stage("inner"):
                pass
        with stage("outer"):
            pass
    assert t.seconds == {"outer": (10 - 1 - 4) + 1.0, "inner": 4.0}  # outer: 9 s less inner's 4, then 1 s more
    assert list(t.seconds) == ["outer", "inner"]  # the order they were entered
    assert t.counts == {"outer": 2, "inner": 1}
    assert t.wall_s == 20.0
    assert t.rows() == [("outer", 6.0), ("inner", 4.0), ("other", 10.0)]
    assert sum(s for _, s in t.rows()) == t.wall_s
    assert t.to_dict() == {"stages": {"outer": 6.0, "inner": 4.0, "other": 10.0}, "wall_s": 20.0}
    assert clock.readings == []


def test_no_collector_no_record_and_no_clock_read():
    with stage("anything"):
        x = 1
    assert x == 1
    outer = StageTimes(Clock())
    assert outer.rows() == [] and outer.to_dict() == {"stages": {}, "wall_s": None}


def test_collectors_nest_and_the_outer_one_is_back_afterwards():
    with collect(compile_times=False, clock=Clock(0.0, 1.0, 2.0, 5.0, 6.0, 7.0, 9.0, 10.0)) as outer:
        with stage("a"):  # 1 -> 2
            pass
        with collect(compile_times=False, clock=Clock(0.0, 1.0, 4.0, 5.0)) as inner:
            with stage("b"):  # 1 -> 4 on the inner clock
                pass
        with stage("c"):  # 5 -> 6
            pass
        with stage("a"):  # 7 -> 9
            pass
    assert inner.seconds == {"b": 3.0} and inner.wall_s == 5.0
    assert outer.seconds == {"a": 3.0, "c": 1.0} and outer.wall_s == 10.0  # b went to the inner collector only


def test_a_stage_that_raises_still_counts_and_collect_closes_what_was_left_open():
    clock = Clock(0.0, 2.0, 5.0, 6.0)
    with pytest.raises(ZeroDivisionError):
        with collect(compile_times=False, clock=clock) as t:
            with stage("boom"):
                1 / 0
    assert t.seconds == {"boom": 3.0} and t.wall_s == 6.0
    t2 = StageTimes(Clock(1.0, 4.0))
    t2._enter("open")
    t2._leave()
    assert t2.seconds == {"open": 3.0}


def test_numba_compilations_get_their_own_row_taken_out_of_the_stage_they_happened_in():
    from numba.core import event

    # collect 0; stage in 1; compile starts 2 (a nested compile inside it: no reading), ends 6; stage out 10; end 11
    clock = Clock(0.0, 1.0, 2.0, 6.0, 10.0, 11.0)
    with collect(clock=clock) as t:
        with stage("migrate"):
            with event.trigger_event("numba:compile"):
                with event.trigger_event("numba:compile"):  # a callee compiled inside: counted once
                    pass
    assert t.seconds == {"migrate": 9.0 - 4.0, "compile": 4.0}
    assert t.counts == {"migrate": 1, "compile": 1}
    assert t.rows() == [("migrate", 5.0), ("compile", 4.0), ("other", 2.0)]
    # the listener is gone with the collector: a compile now counts nowhere
    with event.trigger_event("numba:compile"):
        pass
    assert t.seconds == {"migrate": 5.0, "compile": 4.0}
    # outside any stage a compile is a row of its own, taken from nothing
    with collect(clock=Clock(0.0, 1.0, 3.0, 4.0)) as t3:
        with event.trigger_event("numba:compile"):
            pass
    assert t3.rows() == [("compile", 2.0), ("other", 2.0)]


def test_a_real_compile_is_counted():
    import numba
    import numpy as np

    @numba.njit
    def total(x):
        return x.sum() * 2.0

    with collect() as t:
        with stage("work"):
            assert total(np.ones(4)) == 8.0
    assert t.counts["compile"] == 1 and t.seconds["compile"] > 0
    assert t.seconds["work"] >= 0 and t.seconds["work"] < t.seconds["compile"] + 1.0


def test_the_table_lists_each_stage_with_its_share():
    text = format_table([("read", 1.0), ("migrate", 3.0)], title="T")
    assert text.splitlines() == ["T",
                                 "  stage           s   share",
                                 "  read        1.000   25.0 %",
                                 "  migrate     3.000   75.0 %",
                                 "  total       4.000  100.0 %"]


def test_the_process_age_is_how_long_the_process_has_lived():
    if process_age_s() is None:
        pytest.skip("no /proc here")
    code = ("import time; time.sleep(1.0); from gpr3d.core.timing import process_age_s; a = process_age_s(); "
            "print(a)")
    age = float(subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout)
    assert 0.98 <= age < 120  # /proc counts in clock ticks (1/100 s)
