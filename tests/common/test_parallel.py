"""mavins.common.parallel.run_jobs: item order, failures, a local pool and a real Dask LocalCluster."""

from __future__ import annotations

import os

import numpy as np
import pytest

from mavins.common.parallel import JobError, run_jobs


def seeded_job(seed: int) -> tuple[int, int, np.ndarray]:
    """A job whose result depends on its item only (plus which process ran it, returned apart)."""
    rng = np.random.default_rng(seed)
    return seed, os.getpid(), rng.standard_normal(4)


def failing_job(x: int) -> int:
    if x == 3:
        raise ArithmeticError(f"bad item {x}")
    return x * x


def test_in_process_and_pool_give_the_same_results_in_item_order() -> None:
    items = list(range(12))
    here = run_jobs(seeded_job, items, jobs=1)
    pool = run_jobs(seeded_job, items, jobs=2)
    assert [r[0] for r in pool] == items
    for a, b in zip(here, pool):
        assert np.array_equal(a[2], b[2])
    assert {r[1] for r in here} == {os.getpid()}
    assert os.getpid() not in {r[1] for r in pool}  # really other processes


@pytest.mark.parametrize("jobs", [1, 2])
def test_a_failing_job_names_its_item(jobs: int) -> None:
    with pytest.raises(JobError, match=r"job 3 \(3\) failed: ArithmeticError: bad item 3") as info:
        run_jobs(failing_job, list(range(6)), jobs=jobs)
    assert info.value.index == 3 and info.value.item == 3
    assert isinstance(info.value.__cause__, ArithmeticError)


def test_bad_jobs_is_refused() -> None:
    with pytest.raises(ValueError, match="jobs must be >= 1"):
        run_jobs(failing_job, [1], jobs=0)


def test_dask_local_cluster_runs_the_same_jobs() -> None:
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        items = list(range(8))
        remote = run_jobs(seeded_job, items, cluster=cluster.scheduler_address)
        with pytest.raises(JobError, match=r"job 3 \(3\) failed"):
            run_jobs(failing_job, items, cluster=cluster.scheduler_address)
    local = run_jobs(seeded_job, items, jobs=1)
    assert [r[0] for r in remote] == items
    for a, b in zip(local, remote):
        assert np.array_equal(a[2], b[2])
    assert os.getpid() not in {r[1] for r in remote}
