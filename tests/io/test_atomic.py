"""Atomic writes and the training logs resumed after a kill."""


def test_a_resumed_log_drops_the_rows_after_its_checkpoint(tmp_path):
    from gpr3d.io.atomic import resume_log

    p = tmp_path / "losses.csv"
    with resume_log(p, 0, "step,loss\n") as fh:  # a new run: the header, once
        fh.write("1,0.9\n2,0.8\n3,0.7\n4,0.6\n")
    # killed after step 4, checkpoint at 2: steps 3 and 4 will be done again
    with resume_log(p, 2, "step,loss") as fh:
        fh.write("3,0.71\n")
    assert p.read_text() == "step,loss\n1,0.9\n2,0.8\n3,0.71\n"
    with resume_log(p, 3, "step,loss") as fh:  # nothing after the checkpoint: the file as it was, appended to
        fh.write("4,0.5\n")
    assert p.read_text() == "step,loss\n1,0.9\n2,0.8\n3,0.71\n4,0.5\n"
    with resume_log(p, 0, "step,loss") as fh:  # step 0: a new run starts the log again
        pass
    assert p.read_text() == "step,loss\n"
    q = tmp_path / "none.csv"
    with resume_log(q, 5, "step,loss") as fh:  # a resumed run whose log was removed: a new log
        fh.write("6,0.1\n")
    assert q.read_text() == "step,loss\n6,0.1\n"
