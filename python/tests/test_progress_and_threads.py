"""Progress callbacks, cancelling, and other Python threads running while the device works."""

import threading
import time

import numpy as np
import pytest

import oclvox

# Many batches: 64^3 bricks (32 KiB of bits each) under a 1 MiB device budget.
BATCHED = dict(brick_size=64, device_memory=1)


def test_progress_reports_every_batch(spot):
    calls = []
    grid = oclvox.voxelize(*spot, 512, **BATCHED, progress=lambda done, total: calls.append(
        (done, total)))
    assert len(calls) == grid.stats["batches"] > 1
    totals = {total for _, total in calls}
    assert len(totals) == 1 and calls[-1][0] == totals.pop()
    assert all(a[0] < b[0] for a, b in zip(calls, calls[1:]))
    # Reporting changes nothing.
    assert grid.count == oclvox.voxelize(*spot, 512, **BATCHED).count


@pytest.mark.parametrize("mode", ["surface", "solid"])
def test_returning_false_cancels(spot, mode):
    calls = []

    def stop_after_two(done, total):
        calls.append(done)
        return len(calls) < 2

    with pytest.raises(oclvox.Cancelled):
        oclvox.voxelize(*spot, 512, mode=mode, **BATCHED, progress=stop_after_two)
    assert len(calls) == 2  # stopped at the first report that said so


def test_exception_in_callback_is_raised(spot):
    def fail(done, total):
        raise ZeroDivisionError("from the callback")

    with pytest.raises(ZeroDivisionError, match="from the callback"):
        oclvox.voxelize(*spot, 512, **BATCHED, progress=fail)
    with pytest.raises(TypeError):  # a callback of the wrong signature is an exception too
        oclvox.voxelize(*spot, 512, **BATCHED, progress=lambda: True)
    with pytest.raises(TypeError, match="callable"):
        oclvox.voxelize(*spot, 64, progress=42)


def check_contract(calls):
    """The field functions' progress: one fixed total, done never back, the last call at the end."""
    assert calls, "never called"
    assert len({total for _, total in calls}) == 1
    assert all(a[0] <= b[0] <= b[1] for a, b in zip(calls, calls[1:]))
    assert calls[-1][0] == calls[-1][1]


@pytest.mark.parametrize("reference", [False, True])
def test_sdf_progress_and_cancel(spot, reference):
    calls = []
    field = oclvox.sdf(*spot, 64, reference=reference,
                       progress=lambda done, total: calls.append((done, total)))
    check_contract(calls)
    # Reporting changes nothing.
    assert np.array_equal(field.to_numpy(), oclvox.sdf(*spot, 64, reference=reference).to_numpy())

    calls = []

    def stop(done, total):
        calls.append(done)
        return False

    with pytest.raises(oclvox.Cancelled):
        oclvox.sdf(*spot, 64, reference=reference, progress=stop)
    assert len(calls) == 1  # stopped at the first report
    with pytest.raises(ZeroDivisionError):
        oclvox.sdf(*spot, 64, reference=reference, progress=lambda done, total: 1 / 0)


def test_csg_and_mesh_progress_and_cancel(spot):
    calls = []
    field = oclvox.csg(spot, "difference", spot, 48,
                       progress=lambda done, total: calls.append((done, total)))
    check_contract(calls)
    calls = []
    field.mesh(progress=lambda done, total: calls.append((done, total)))
    check_contract(calls)
    with pytest.raises(oclvox.Cancelled):
        oclvox.csg(spot, "union", spot, 48, progress=lambda done, total: False)
    with pytest.raises(oclvox.Cancelled):
        oclvox.mesh(field, progress=lambda done, total: False)


def test_save_progress_and_cancel(spot, tmp_path):
    grid = oclvox.voxelize(*spot, 96)
    calls = []
    grid.save(tmp_path / "a.npy", progress=lambda done, total: calls.append((done, total)))
    assert calls and calls[-1][0] == calls[-1][1]
    assert all(a[0] <= b[0] for a, b in zip(calls, calls[1:]))
    assert np.array_equal(np.load(tmp_path / "a.npy"), grid.to_numpy())
    with pytest.raises(oclvox.Cancelled):
        grid.save(tmp_path / "b.vdb", progress=lambda done, total: False)

    def fail(done, total):
        raise KeyError("from the callback")

    with pytest.raises(KeyError, match="from the callback"):
        grid.save(tmp_path / "c.binvox", progress=fail)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.npy", "a.npy.json"]


def test_mesh_files_load_and_save_with_progress_and_cancel(spot, tmp_path):
    vertices, faces = spot
    calls = []
    oclvox.save_mesh(tmp_path / "spot.ply", vertices, faces,
                     progress=lambda done, total: calls.append((done, total)))
    check_contract(calls)
    calls = []
    loaded = oclvox.load_mesh(tmp_path / "spot.ply",
                              progress=lambda done, total: calls.append((done, total)))
    check_contract(calls)
    assert np.array_equal(loaded[1], oclvox.load_mesh(tmp_path / "spot.ply")[1])
    with pytest.raises(oclvox.Cancelled):
        oclvox.load_mesh(tmp_path / "spot.ply", progress=lambda done, total: False)
    with pytest.raises(oclvox.Cancelled):
        oclvox.save_mesh(tmp_path / "other.obj", vertices, faces,
                         progress=lambda done, total: False)
    assert not (tmp_path / "other.obj").exists()


def test_cancel_stops_a_long_sdf_promptly(spot):
    # A full-grid 256^3 field takes minutes through PoCL (and well under a second on a large GPU);
    # a callback that says stop at its first report past the start, before the end, must end the
    # run soon after (kernels run in slices of about 0.1 s while a callback is set). Stopping at a
    # report rather than after a fixed time keeps the test meaningful on a device that finishes
    # the field before that time would come.
    reports, stopped = [], []

    def progress(done, total):
        if not stopped and reports and done < total:
            stopped.append(time.perf_counter())
        reports.append(done)
        return not stopped

    with pytest.raises(oclvox.Cancelled):
        oclvox.sdf(*spot, 256, full_grid=True, progress=progress)
    assert time.perf_counter() - stopped[0] < 2.0


def run_while_ticking(spot, resolution):
    """Voxelizes in a worker thread while the main thread ticks; returns (span, ticks)."""
    span = {}

    def work():
        span["start"] = time.perf_counter()
        span["count"] = oclvox.voxelize(*spot, resolution, **BATCHED).count
        span["end"] = time.perf_counter()

    worker = threading.Thread(target=work)
    ticks = []
    worker.start()
    while worker.is_alive():
        ticks.append(time.perf_counter())
        time.sleep(0.001)
    worker.join()
    return span, ticks


def test_another_thread_runs_during_device_work(spot):
    # While a voxelization runs, the main thread keeps ticking: if the GIL were held by the call,
    # no tick could happen between its start and its end. The run must last long enough to tell,
    # which depends on the machine (and on how fast voxelizing has become: 3072^3 took 0.28 s on
    # two cores at d169782), so the grid grows until it does; 0.2 s is 200 ticks.
    for resolution in (768, 1280, 2048, 3072, 4096):
        span, ticks = run_while_ticking(spot, resolution)
        duration = span["end"] - span["start"]
        if duration > 0.2:
            break
    assert span["count"] > 0
    assert duration > 0.2, "even the largest run is too short to tell"
    inside = np.array([t for t in ticks if span["start"] < t < span["end"]])
    # Ticks all through the run: no gap longer than a third of it.
    gaps = np.diff(np.concatenate([[span["start"]], inside, [span["end"]]]))
    assert gaps.max() < duration / 3, (gaps.max(), duration)


def test_threads_share_a_device(spot):
    # Two threads voxelizing at once on the one cached device both get the right answer.
    expected = oclvox.voxelize(*spot, 200).to_numpy()
    results = [None, None]

    def work(slot):
        results[slot] = oclvox.voxelize(*spot, 200).to_numpy()

    threads = [threading.Thread(target=work, args=(slot,)) for slot in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert all(np.array_equal(r, expected) for r in results)
