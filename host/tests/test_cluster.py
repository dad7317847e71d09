"""The fast kernel over a Dask cluster, and which clusters eelbot agrees to trust.

A cluster runs code on the client (Dask moves pickles both ways), so eelbot connects with TLS and
certificates, or plain TCP on this machine only, unless told ``--insecure`` (docs/cli.md,
"Security"). The batched backend sends blocks of candidates as tasks; each worker process keeps
its kernel loaded.
"""

from __future__ import annotations

import json

import distributed  # a dev dependency, installed by setup
import numpy as np
import pytest

from eelhost.cli import main
from eelhost.data.experiments import load_dataset, manifest_text, write_experiment, write_manifest
from eelhost.data.virtual_tank import TABLE3, TankSettings, record_experiment
from eelhost.estimation import cluster
from eelhost.estimation.cluster import ClusterError, TLSFiles, dask_map, security_for
from eelhost.estimation.evaluate import Evaluator
from eelsim.robot import load_robot
from eelsim.scenario import load_scenario

TRUTH = TABLE3["straight"]


@pytest.fixture(scope="module")
def small_dataset(tmp_path_factory):
    """Two short straight experiments recorded with the table-3 truth."""
    folder = tmp_path_factory.mktemp("small")
    robot = load_robot()
    names = ["straight_A0.87_w3.9", "straight_A0.61_w2.7"]
    for i, name in enumerate(names):
        s = load_scenario(name).model_copy(update={"waypoints_m": [(0.5, 0.0)]})
        exp = record_experiment(robot, s, "straight", TRUTH, TankSettings(timestamp_jitter_s=0.0),
                                seed=i)
        write_experiment(exp, folder)
    write_manifest(folder, manifest_text("paper_robot.toml",
                                         {"straight": {"train": names, "test": []}}, []))
    return folder


@pytest.fixture(scope="module")
def tls_files(tmp_path_factory):
    """A throwaway self-signed certificate (its own authority) for the cluster and the client."""
    sec = distributed.Security.temporary()
    folder = tmp_path_factory.mktemp("tls")
    (folder / "cert.pem").write_text(sec.tls_client_cert)
    (folder / "key.pem").write_text(sec.tls_client_key)
    return sec, TLSFiles(str(folder / "cert.pem"), str(folder / "cert.pem"), str(folder / "key.pem"))


def _worker_address(job: tuple) -> str:
    shared, _ = job
    assert shared.shape == (4, 1000)  # the shared value arrives, not its future
    return distributed.get_worker().address


def _kernels_loaded() -> int:
    from eelsim.batch import loading

    return len(loading._KERNELS)


@pytest.mark.parametrize("address", ["tcp://10.0.0.5:8786", "192.168.1.20:8786",
                                     "tcp://scheduler.lab:8786", "tcp://0.0.0.0:8786"])
def test_plain_tcp_to_another_machine_is_refused_unless_insecure(address):
    with pytest.raises(ClusterError, match="plain TCP to another machine is refused.*--insecure"):
        security_for(address)
    assert security_for(address, insecure=True) is None


@pytest.mark.parametrize("address", ["tcp://127.0.0.1:8786", "tcp://localhost:8786",
                                     "tcp://[::1]:8786", "127.0.0.2:8786"])
def test_plain_tcp_on_this_machine_is_allowed(address):
    assert security_for(address) is None


def test_tls_needs_an_authority_and_a_client_certificate(tmp_path, monkeypatch):
    import dask

    with dask.config.set({"distributed.comm.tls.ca-file": None,
                          "distributed.comm.tls.client.cert": None}), \
            pytest.raises(ClusterError, match="--tls-ca-file and --tls-cert"):
        security_for("tls://10.0.0.5:8786")
    with pytest.raises(ClusterError, match="protocol ws:// is not supported"):
        security_for("ws://10.0.0.5:8786")


def test_tls_certificates_come_from_the_options_or_the_dask_config(tls_files):
    import dask

    _, files = tls_files
    sec = security_for("tls://10.0.0.5:8786", files)
    assert sec.require_encryption and sec.tls_ca_file == files.ca_file
    with dask.config.set({"distributed.comm.tls.ca-file": files.ca_file,
                          "distributed.comm.tls.client.cert": files.cert,
                          "distributed.comm.tls.client.key": files.key}):
        sec = security_for("tls://10.0.0.5:8786")
    assert sec.tls_client_cert == files.cert and sec.tls_client_key == files.key


@pytest.mark.slow
def test_the_batched_kernel_over_a_tls_cluster_of_processes_gives_the_local_fitness(
    small_dataset, tls_files, tmp_path, capsys
):
    ds = load_dataset(small_dataset)
    rng = np.random.default_rng(3)
    cands = TRUTH.as_array() * rng.uniform(0.7, 1.3, size=(9, 4))
    local = Evaluator(ds.robot, ds.train["straight"], backend="batch")
    expected = local.fitness(cands)
    sec, files = tls_files
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  protocol="tls://", security=sec, dashboard_address=None,
                                  silence_logs=40) as lab:
        assert lab.scheduler_address.startswith("tls://")
        spread_map = dask_map(lab.scheduler_address, tls=files)
        assert spread_map.workers == 2 and spread_map.blocks == 4
        # blocks that all hold the shared experiments are dealt round the workers (left to
        # itself, the scheduler put them all on one)
        shared = spread_map.share(np.zeros((4, 1000)))
        assert len(set(spread_map(_worker_address, [(shared, i) for i in range(4)]))) == 2
        spread = Evaluator(ds.robot, ds.train["straight"], backend="batch",
                           map_function=spread_map)
        assert np.array_equal(spread.fitness(cands), expected)
        assert np.array_equal(spread.fitness(cands[::-1]), expected[::-1])  # learnt lengths
        # both worker processes ran blocks, each loading the kernel once and keeping it
        kernels = spread_map.client.run(_kernels_loaded)
        assert sorted(kernels.values()) == [1, 1]
        spread_map.client.close()
        # plain TCP to a TLS scheduler is not an open door
        with pytest.raises(ClusterError):
            dask_map(lab.scheduler_address.replace("tls://", "tcp://"), timeout_s=2.0)
        # the command: a GA of two generations on the cluster
        out = tmp_path / "fit"
        argv = ["estimate", str(small_dataset), "--motion", "straight", "--method", "ga",
                "--pop-size", "6", "--generations", "2", "--no-fit-current", "--out", str(out),
                "--scheduler", lab.scheduler_address, "--tls-ca-file", files.ca_file,
                "--tls-cert", files.cert, "--tls-key", files.key]
        assert main(argv) == 0, capsys.readouterr().err
    fits = json.loads((out / "coefficients.json").read_text())["fits"]
    assert fits["straight"]["evaluations"] == 12


def test_the_estimate_command_refuses_plain_tcp_elsewhere_before_connecting(small_dataset,
                                                                             tmp_path, capsys,
                                                                             monkeypatch):
    monkeypatch.setattr(cluster, "CONNECT_TIMEOUT_S", 0.5)
    argv = ["estimate", str(small_dataset), "--scheduler", "tcp://10.0.0.5:8786", "--out",
            str(tmp_path / "fit")]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "plain TCP to another machine is refused" in err and "--insecure" in err


def test_the_cluster_benchmark_block_is_replaced_in_place_and_survives_a_bench_rewrite(tmp_path):
    from eelhost.benchmarks.cluster_speed import BEGIN, END, keep_block, write_block

    page = tmp_path / "benchmarks.md"
    page.write_text("# Benchmarks\n\nsection 1\n")
    write_block(page, f"{BEGIN}\nfirst\n{END}")
    write_block(page, f"{BEGIN}\nsecond\n{END}")
    text = page.read_text()
    assert text.count(BEGIN) == 1 and "second" in text and "first" not in text
    assert text.startswith("# Benchmarks\n\nsection 1\n")
    rewritten = keep_block(page, "# Benchmarks\n\nnew section 1\n")  # what eelbot bench writes
    assert rewritten.startswith("# Benchmarks\n\nnew section 1\n") and "second" in rewritten


class _NoWorkersClient:
    """A client whose scheduler reports no worker (one registering, or a report lagging under
    load), with Dask's own refusal of ``allow_other_workers`` without ``workers``."""

    def scheduler_info(self):  # noqa: ANN201
        return {"workers": {}}

    def submit(self, function, job, pure=True, workers=None, allow_other_workers=False):  # noqa: ANN001, ANN201, FBT002
        if allow_other_workers and workers is None:
            raise ValueError("Only use allow_other_workers= if using workers=")
        return function(job)

    def gather(self, futures):  # noqa: ANN001, ANN201
        return list(futures)


def test_jobs_run_when_the_scheduler_reports_no_worker_for_a_moment():
    # a loaded fresh clone's cluster test failed here: the jobs were dealt round an empty list
    # of workers with allow_other_workers, which Dask refuses
    spread = cluster.ClusterMap(_NoWorkersClient())
    assert spread.workers == 1
    assert spread(lambda x: 2 * x, [1, 2, 3]) == [2, 4, 6]
