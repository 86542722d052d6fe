"""Folders on a dask.distributed cluster: the local path's results, a killed worker survived, few compiles."""

import json
import os
import signal
from pathlib import Path

import jax
import pytest

import wardjax as wj
from wardjax.run import CompileCounter, cluster_compiles, open_scheduler, run_batch
from wardjax.run._distributed import parse_scheduler, worker_env

DESK = wj.WardParams(rho_d=(0.676,) * 3, rho_s=0.039, alpha_x=0.137, alpha_y=0.150)
# Three image sizes whose probe bands fall in different shape buckets.
SIZES = ((96, 72), (128, 96), (160, 120))


# Entry points compiled for two values of a static argument per shape: the texture-field lobe, in the fit's
# normalisation and again in Radiance's (the export's refit).
SPECIALISATIONS = {"jit(_lobe_and_grad)": 2}


def _entry_points(counts) -> dict[str, int]:
    """Compiles per jitted wardjax entry point, per static specialisation; eager ``jax.lax`` ops left out.

    An eager op (``jnp.asarray`` → ``convert_element_type``, ``stage``) is compiled per shape and dtype
    it meets, like any op, and is not an entry point of the library.
    """
    out = {}
    for name, n in counts.items():
        inner = name.removeprefix("jit(").removesuffix(")")
        if not hasattr(jax.lax, inner):
            out[name] = -(-n // SPECIALISATIONS.get(name, 1))
    return out


def _tree(folder: Path) -> dict:
    """Every file under ``folder`` (hidden ones too); ``params.json`` parsed, without its ``created`` timestamp."""
    out = {}
    for f in sorted(folder.rglob("*")):
        if f.is_file():
            data = f.read_bytes()
            if f.name == "params.json":
                doc = json.loads(data)
                assert isinstance(doc.pop("created"), str)
                data = doc
            out[str(f.relative_to(folder))] = data
    return out


def _close(a, b, path="") -> list[str]:
    """Where two JSON documents differ: structure and strings exactly, numbers to 10⁻¹² relative.

    Workers hold BLAS and XLA to one thread each; this process uses both cores, and a sum split over
    two threads may round its last bit differently (seen: χ² and the model covariance's σ, 1 ulp).
    """
    if isinstance(a, dict) and isinstance(b, dict):
        if a.keys() != b.keys():
            return [f"{path}: keys {sorted(a.keys() ^ b.keys())}"]
        return [d for k in a for d in _close(a[k], b[k], f"{path}.{k}")]
    if isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            return [f"{path}: lengths {len(a)} {len(b)}"]
        return [d for i, (x, y) in enumerate(zip(a, b)) for d in _close(x, y, f"{path}[{i}]")]
    if isinstance(a, float) and isinstance(b, float):
        return [] if abs(a - b) <= 1e-12 * max(abs(a), abs(b)) else [f"{path}: {a} {b}"]
    return [] if a == b else [f"{path}: {a!r} {b!r}"]


def test_scheduler_specs():
    assert parse_scheduler("local:3") == ("local", 3)
    assert parse_scheduler("local")[1] >= 1
    assert parse_scheduler("tcp://10.0.0.5:8786") == ("address", "tcp://10.0.0.5:8786")
    for bad in ("local:0", "local:x", "locals", ""):
        with pytest.raises(ValueError, match="^--scheduler ") as e:
            parse_scheduler(bad)
        assert "\n" not in str(e.value)
    env = worker_env(1)
    assert "--xla_cpu_multi_thread_eigen=false" in env["XLA_FLAGS"] and env["OMP_NUM_THREADS"] == "1"
    assert "intra_op_parallelism_threads=4" in worker_env(4)["XLA_FLAGS"]


def test_cli_refuses_a_bad_scheduler_in_one_line(tmp_path):
    from click.testing import CliRunner

    from wardjax.run._cli import main

    (tmp_path / "c").mkdir()
    res = CliRunner().invoke(main, ["fit", str(tmp_path / "c"), "--out", str(tmp_path / "o"), "--scheduler", "local:0"])
    assert res.exit_code == 2
    assert res.output.strip().splitlines() == ["error: --scheduler 'local:0': local:N needs at least 1 worker"]


@pytest.mark.slow
def test_cluster_with_a_killed_worker_ends_as_the_local_path(tmp_path):
    # Ten captures of three sizes; the local path fits them in this process, a LocalCluster of two worker
    # processes fits them again while one busy worker is killed (SIGKILL) as the first result lands. The
    # cluster's results must be the local path's file for file (the timestamp aside), no capture written
    # again after its result was recorded, and no program compiled more than once per size bucket
    # (≤ 3 per entry point) in this process or in any worker.
    caps = tmp_path / "captures"
    for i in range(10):
        wj.simulate_capture(DESK, caps / f"c{i:02d}", seed=i, image_size=SIZES[i % 3], texture="wood")
    # Workers run JAX with its default settings; so does the reference (tests/conftest.py raises on rank
    # promotion, which wardjax.texture.analyze_texture, behind texture.json, relies on).
    with jax.numpy_rank_promotion("allow"), CompileCounter() as local:
        ref_items = run_batch([caps], tmp_path / "ref")
    assert all(it.status == "ok" for it in ref_items)
    local_entry = _entry_points(local.counts)
    assert len(local_entry) > 10 and max(local_entry.values()) <= 3, local.counts.most_common(8)

    out = tmp_path / "cluster"
    killed: list[int] = []
    mtimes: dict[str, int] = {}
    with open_scheduler("local:2", cache_dir=str(tmp_path / "xla")) as client:

        def progress(i, n, item):
            mtimes[item.name] = (out / item.name / "params.json").stat().st_mtime_ns
            if killed:
                return
            busy = [a for a, keys in client.processing().items() if keys]
            assert busy, "no task left running to kill the worker of"
            pid = client.run(os.getpid, workers=busy[:1])[busy[0]]
            os.kill(pid, signal.SIGKILL)
            killed.append(pid)

        items = run_batch([caps], out, scheduler=client, progress=progress)
        compiles = cluster_compiles(client)
    assert killed and [it.status for it in items] == ["ok"] * 10
    assert [it.name for it in items] == [it.name for it in ref_items]
    got, want = _tree(out), _tree(tmp_path / "ref")
    assert got.keys() == want.keys()
    assert _close(got, want) == []
    assert all(got[k] == want[k] for k in got if not k.endswith("params.json"))  # every other file: bit for bit
    assert mtimes == {n: (out / n / "params.json").stat().st_mtime_ns for n in mtimes} and len(mtimes) == 10
    assert len(compiles) == 2 and any(compiles.values())
    for c in compiles.values():
        entry = _entry_points(c)
        assert not entry or max(entry.values()) <= 3, sorted(c.items(), key=lambda kv: -kv[1])[:8]
    print(
        "\nlocal: compiles by entry point", sorted(local_entry.items()), "eager", len(local.counts) - len(local_entry)
    )
    for w, c in compiles.items():
        print("worker", w, "compiles by entry point", sorted(_entry_points(c).items()))
