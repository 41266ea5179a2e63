import math

import pytest

from roadload.sweep import failures, run_sweep


def _work(task):
    if task == 3:
        raise ValueError("task three is broken")
    return {"task": task, "value": math.sqrt(task) * 7.0}


def test_local_sweep_keeps_order_and_reports_failures():
    out = run_sweep(_work, range(6), progress=False, workers=2)
    assert [o.index for o in out] == list(range(6))
    assert [o.value["task"] for o in out if o.ok] == [0, 1, 2, 4, 5]
    bad = failures(out)
    assert len(bad) == 1 and bad[0].task == 3 and bad[0].error == "ValueError: task three is broken"
    assert "Traceback" in bad[0].traceback
    serial = run_sweep(_work, range(6), progress=False, workers=1)
    assert [o.value for o in serial] == [o.value for o in out]


def test_dask_local_cluster_gives_the_same_results():
    # workers import fn by name: use an importable function (test modules are not importable there)
    distributed = pytest.importorskip("distributed")
    tasks = [4.0, 2.0, -1.0, 9.0, 0.5]
    local = run_sweep(math.sqrt, tasks, progress=False, workers=1)
    assert local[2].error == "ValueError: math domain error"
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cl:
        remote = run_sweep(math.sqrt, tasks, scheduler=cl.scheduler_address, progress=False)
    assert [(o.index, o.value, o.error) for o in remote] == [(o.index, o.value, o.error) for o in local]
