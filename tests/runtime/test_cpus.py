"""pmdcid.runtime.cpus: pieces shared with the spare CPUs, never more threads than CPUs,
results in order whatever thread ran them."""

from __future__ import annotations

import os
import threading
import time

import pytest

import pmdcid.runtime.cpus as cpus


def test_workers_follow_affinity_and_env(monkeypatch):
    monkeypatch.delenv("PMDCID_THREADS", raising=False)
    n = len(os.sched_getaffinity(0))
    assert cpus.workers() == n
    monkeypatch.setenv("PMDCID_THREADS", "1")
    assert cpus.workers() == 1
    monkeypatch.setenv("PMDCID_THREADS", "64")
    assert cpus.workers() == n  # never more threads than CPUs
    monkeypatch.setenv("PMDCID_THREADS", "many")
    assert cpus.workers() == n


@pytest.mark.parametrize("n", [1, 2, 3])
def test_nested_maps_keep_order_and_never_exceed_the_cpus(monkeypatch, n):
    monkeypatch.setattr(cpus, "workers", lambda: n)
    busy, peak, lock = [0], [0], threading.Lock()

    def leaf(x):
        with lock:
            busy[0] += 1
            peak[0] = max(peak[0], busy[0])
        time.sleep(0.002)
        with lock:
            busy[0] -= 1
        return x * x

    def middle(k):
        return cpus.pmap(leaf, range(10 * k, 10 * k + 7))

    got = cpus.pmap(middle, range(5))
    assert got == [[x * x for x in range(10 * k, 10 * k + 7)] for k in range(5)]
    assert 1 <= peak[0] <= n
    if n > 1:
        assert peak[0] > 1  # the spare CPU did help


def test_first_error_in_item_order_after_every_piece(monkeypatch):
    monkeypatch.setattr(cpus, "workers", lambda: 2)
    ran = []

    def fn(x):
        ran.append(x)
        if x in (2, 4):
            raise ValueError(f"piece {x}")
        return x

    with pytest.raises(ValueError, match="piece 2"):
        cpus.pmap(fn, range(6))
    assert sorted(ran) == list(range(6))
    assert cpus.pmap(fn, [0, 1], parallel=False) == [0, 1]
