"""gpr3d.core.timing: stages timed on a clock that the test holds, so every second is known in advance."""

import os
import subprocess
import sys
import time

import pytest

from gpr3d.core.timing import StageTimes, age_from_proc, collect, format_table, process_age_s, stage


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


def test_collectors_nest_each_sees_every_stage_inside_it_and_the_outer_one_is_back_afterwards():
    outer_clock = Clock(0.0, 1.0, 2.0, 3.0, 7.0, 8.0, 9.0, 10.0, 11.0, 12.0)
    inner_clock = Clock(0.0, 1.0, 4.0, 5.0)
    with collect(compile_times=False, clock=outer_clock) as outer:
        with stage("a"):  # 1 -> 2
            pass
        with collect(compile_times=False, clock=inner_clock) as inner:
            with stage("b"):  # 3 -> 7 on the outer clock, 1 -> 4 on the inner one
                pass
        with stage("c"):  # 8 -> 9
            pass
        with stage("a"):  # 10 -> 11
            pass
    assert inner.seconds == {"b": 3.0} and inner.wall_s == 5.0
    assert outer.seconds == {"a": 2.0, "b": 4.0, "c": 1.0} and outer.wall_s == 12.0
    assert outer_clock.readings == [] and inner_clock.readings == []
    with stage("after"):  # nobody collects any more
        pass
    assert "after" not in outer.seconds


def test_two_inner_stages_and_two_compilations_are_all_taken_from_their_outer_stage():
    from numba.core import event

    # collect 0; outer in 1; a 2 -> 3; b 4 -> 6; compile 7 -> 8; compile 9 -> 11; outer out 20; end 20
    clock = Clock(0.0, 1.0, 2.0, 3.0, 4.0, 6.0, 7.0, 8.0, 9.0, 11.0, 20.0, 20.0)
    with collect(clock=clock) as t:
        with stage("outer"):
            with stage("a"):
                pass
            with stage("b"):
                pass
            with event.trigger_event("numba:compile"):
                pass
            with event.trigger_event("numba:compile"):
                pass
    assert t.seconds == {"outer": 19.0 - 1.0 - 2.0 - 1.0 - 2.0, "a": 1.0, "b": 2.0, "compile": 3.0}
    assert t.counts["compile"] == 2
    assert t.rows() == [("outer", 13.0), ("a", 1.0), ("b", 2.0), ("compile", 3.0), ("other", 1.0)]


def test_a_compilation_is_timed_from_its_outermost_start_to_its_outermost_end():
    from numba.core import event

    # collect 0; compile starts 1; inside it, after a nested compile, a stage 2 -> 3; compile ends 5; end 6
    clock = Clock(0.0, 1.0, 2.0, 3.0, 5.0, 6.0)
    with collect(clock=clock) as t:
        with event.trigger_event("numba:compile"):
            with event.trigger_event("numba:compile"):
                pass
            with stage("inside"):
                pass
    assert t.seconds == {"compile": 4.0, "inside": 1.0} and t.counts["compile"] == 1


def test_other_is_the_time_no_stage_claimed_and_only_when_there_is_some():
    with collect(compile_times=False, clock=Clock(0.0, 0.0, 4.0, 4.0)) as t:
        with stage("all"):
            pass
    assert t.rows() == [("all", 4.0)]  # nothing left over: no 'other' row
    with collect(compile_times=False, clock=Clock(0.0, 0.0, 4.0, 4.5)) as t:
        with stage("most"):
            pass
    assert t.rows() == [("most", 4.0), ("other", 0.5)]
    with collect(compile_times=False, clock=Clock(0.0, 1.0, 2.23456789, 3.0)) as t:
        with stage("x"):
            pass
    assert t.to_dict() == {"stages": {"x": 1.234568, "other": 1.765432}, "wall_s": 3.0}
    t.wall_s = 3.123456789
    assert t.to_dict()["wall_s"] == 3.123457


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
    assert t.counts["compile"] == 1 and t.seconds["compile"] > 0 and t.seconds["work"] >= 0
    assert t.seconds["work"] + t.seconds["compile"] <= t.wall_s


def test_the_table_lists_each_stage_with_its_share():
    assert format_table([("a", 1.0)]).splitlines() == ["where the time went", "  stage         s   share",
                                                       "  a         1.000  100.0 %", "  total     1.000  100.0 %"]
    assert format_table([("a", 0.0)]).splitlines()[2] == "  a         0.000    0.0 %"
    text = format_table([("read", 1.0), ("migrate", 3.0)], title="T")
    assert text.splitlines() == ["T",
                                 "  stage           s   share",
                                 "  read        1.000   25.0 %",
                                 "  migrate     3.000   75.0 %",
                                 "  total       4.000  100.0 %"]


def test_a_process_s_age_from_its_proc_lines_by_hand():
    # field 22 (start, in ticks since boot) is the 20th after the name; a name may hold spaces and parentheses
    fields = " ".join(str(v) for v in range(3, 52))  # field k holds k: the start is 22
    stat = f"4242 (odd ) name (x)) {fields}\n"
    assert stat.rsplit(")", 1)[1].split()[19] == "22"
    assert age_from_proc(stat, "100.50 380.25\n", 100) == pytest.approx(100.5 - 0.22)
    assert age_from_proc(stat, "100.50 380.25\n", 10) == pytest.approx(100.5 - 2.2)


def test_the_process_age_is_how_long_this_process_has_lived():
    if not os.path.exists("/proc/self/stat"):
        pytest.skip("no /proc here")
    import psutil

    age = process_age_s()
    # psutil counts from the boot time (whole seconds) instead of the uptime: within a second and a half
    assert age == pytest.approx(time.time() - psutil.Process().create_time(), abs=1.5)
    assert age > 0
    code = ("import time; time.sleep(1.0); from gpr3d.core.timing import process_age_s; a = process_age_s(); "
            "print(a)")
    age = float(subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout)
    assert 0.98 <= age < 120  # /proc counts in clock ticks (1/100 s)


def test_a_clock_that_fails_at_the_end_still_ends_the_collection():
    with pytest.raises(IndexError):
        with collect(compile_times=False, clock=Clock(0.0)) as t:
            pass
    with stage("later"):
        pass
    assert t.seconds == {}
