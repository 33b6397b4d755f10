"""Running a batch: local process pool and a real Dask LocalCluster give the same results;
bad sessions are isolated; a killed worker's task runs again; a rerun resumes."""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
import signal
import threading
import time

import pytest

from batch import run_batch, write_simulated_campaign
from batch.outputs import TABLE_CSV_START, TABLE_FORMAT, OutputLayout
from sysid.core.errors import HelmetAncError
from sysid.core.files import OutputRefused, is_ours
from tests.batch_sessions import BATCH_OPTIONS, SHORT_SESSION, data_columns

distributed = pytest.importorskip("distributed")


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    root = tmp_path_factory.mktemp("campaign")
    # One helmet (a single-mode random plant) on four heads: every session identifies in about a second.
    truths = write_simulated_campaign(root, helmets=1, heads=4, path="fb", seed=3, **SHORT_SESSION)
    return root, truths


@pytest.fixture(scope="module")
def local_run(campaign, tmp_path_factory):
    out = tmp_path_factory.mktemp("local") / "out"
    return run_batch(campaign[0], out, workers=2, options=BATCH_OPTIONS)


def _model_bytes(layout: OutputLayout, rows) -> dict[str, bytes]:
    return {row["session"]: (layout.root / row["model_file"]).read_bytes() for row in rows}


class TestLocalPool:
    def test_every_session_identified_once(self, local_run, campaign):
        rows = local_run.rows
        assert sorted(r["session"] for r in rows) == sorted(f"H0_head{k}_fb" for k in range(4))
        assert [r["status"] for r in rows] == ["ok"] * 4, [r["reason"] for r in rows]
        assert all(r["rms"] > 0 and r["noise_floor"] > 0 and r["order"] >= 1 for r in rows)
        assert all(0 < r["seconds_cpu"] for r in rows)

    def test_outputs_carry_the_input_hash(self, local_run):
        layout = local_run.layout
        for row in local_run.rows:
            model = json.loads((layout.root / row["model_file"]).read_text())
            record = json.loads(layout.result(row["session"]).read_text())
            assert model["identification"]["batch"]["input_hash"] == row["input_hash"] == record["input_hash"]
        table = json.loads(layout.table_json.read_text())
        assert table["format"] == TABLE_FORMAT
        assert [r["session"] for r in table["rows"]] == [r["session"] for r in local_run.rows]
        assert layout.table_csv.read_text().startswith(TABLE_CSV_START)
        assert layout.table_csv.read_text().count("\n") == 1 + len(local_run.rows)

    def test_nominal_model_per_helmet_with_its_bound(self, local_run):
        assert sorted(local_run.nominals) == [("H0", "fb")]
        data = json.loads(local_run.layout.nominal("H0_fb").read_text())
        assert data["format"] == "helmet-anc/model@1"
        band = data["uncertainty"]
        assert len(band["frequencies_hz"]) == len(band["relative_95"]) > 100
        assert min(band["relative_95"]) >= 0.0

    def test_summary_page_is_self_contained(self, local_run):
        page = local_run.layout.summary.read_text()
        assert page.count("data:image/png;base64,") == 1
        assert "http://" not in page and "https://" not in page
        assert "Worst sessions" in page


class TestDask:
    def test_same_results_as_the_local_pool_bit_for_bit(self, campaign, local_run, tmp_path):
        # Worker processes, as on a real cluster (in-process workers share one BLAS thread setting).
        with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, \
                distributed.Client(cluster) as client:
            result = run_batch(campaign[0], tmp_path / "out", scheduler=client, options=BATCH_OPTIONS)
        assert [data_columns(r) for r in result.rows] == [data_columns(r) for r in local_run.rows]
        assert _model_bytes(result.layout, result.rows) == _model_bytes(local_run.layout, local_run.rows)
        for key, nominal in result.nominals.items():
            assert (result.layout.nominal(f"{key[0]}_{key[1]}").read_bytes()
                    == local_run.layout.nominal(f"{key[0]}_{key[1]}").read_bytes())

    @pytest.mark.slow
    def test_worker_killed_during_a_task_and_every_session_done_once(self, campaign, local_run, tmp_path):
        with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, \
                distributed.Client(cluster) as client:
            pids = client.run(os.getpid)
            killed = {}

            def kill_a_busy_worker():
                # Wait for a worker to start a session task, let it work a moment, then kill its process.
                deadline = time.monotonic() + 60
                while time.monotonic() < deadline and not killed:
                    busy = [address for address, keys in client.processing().items() if keys]
                    if busy:
                        time.sleep(0.3)
                        tasks = client.processing()[busy[0]]
                        killed.update(address=busy[0], tasks=list(tasks))
                        os.kill(pids[busy[0]], signal.SIGKILL)
                    time.sleep(0.05)

            killer = threading.Thread(target=kill_a_busy_worker)
            killer.start()
            seen = []
            result = run_batch(campaign[0], tmp_path / "out", scheduler=client, options=BATCH_OPTIONS,
                               progress=lambda done, total, row: seen.append(row["session"]))
            killer.join()
        assert killed["tasks"], "no task was running on the killed worker"
        assert sorted(seen) == sorted(r["session"] for r in local_run.rows)  # each session reported once
        assert [r["status"] for r in result.rows] == ["ok"] * 4, [r["reason"] for r in result.rows]
        assert [data_columns(r) for r in result.rows] == [data_columns(r) for r in local_run.rows]
        assert sorted(p.name for p in (result.layout.root / "models").iterdir()) == \
            sorted(f"{r['session']}.json" for r in result.rows)


class TestFaults:
    def test_corrupt_session_isolated_with_its_reason(self, campaign, tmp_path):
        root, _ = campaign
        bad = tmp_path / "sessions"
        for folder in ("H0/head0/fb", "H0/head1/fb"):
            (bad / folder).mkdir(parents=True)
            for name in ("noise.wav", "sweep1.wav", "sweep2.wav"):
                (bad / folder / name).write_bytes((root / folder / name).read_bytes())
        (bad / "H0/head1/fb/noise.wav").write_bytes(b"RIFF\x00\x00garbage")
        with distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=False, dashboard_address=None) as cluster, \
                distributed.Client(cluster) as client:
            result = run_batch(bad, tmp_path / "out", scheduler=client, options=BATCH_OPTIONS)
        good, broken = result.rows
        assert good["status"] == "ok"
        assert broken["status"] == "failed"
        assert "RecordingError" in broken["reason"] and "noise.wav: not a readable WAV file" in broken["reason"]
        assert result.failed == 1
        assert not result.layout.model(broken["session"]).exists()
        assert "H0_head1_fb: RecordingError" in result.layout.summary.read_text()


class TestResume:
    def test_rerun_skips_finished_and_redoes_changed_sessions(self, campaign, local_run, tmp_path):
        root, _ = campaign
        sessions = tmp_path / "sessions"
        shutil.copytree(root, sessions)
        out = tmp_path / "out"
        shutil.copytree(local_run.layout.root, out)
        stamps = {r["session"]: (out / "results" / f"{r['session']}.json").stat().st_mtime_ns for r in local_run.rows}
        with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None) as cluster, \
                distributed.Client(cluster) as client:
            second = run_batch(sessions, out, scheduler=client, options=BATCH_OPTIONS)
            assert second.resumed == 4
            assert {r["session"]: second.layout.result(r["session"]).stat().st_mtime_ns for r in second.rows} == stamps
            assert [data_columns(r) for r in second.rows] == [data_columns(r) for r in local_run.rows]

            # A changed recording is redone; the others are not.
            (sessions / "H0/head2/fb/sweep2.wav").write_bytes((root / "H0/head3/fb/sweep2.wav").read_bytes())
            third = run_batch(sessions, out, scheduler=client, options=BATCH_OPTIONS)
        assert [r["session"] for r in third.rows if not r["resumed"]] == ["H0_head2_fb"]
        changed = next(r for r in third.rows if r["session"] == "H0_head2_fb")
        assert changed["input_hash"] != next(r for r in local_run.rows if r["session"] == "H0_head2_fb")["input_hash"]

    def test_other_options_redo_everything(self, campaign, local_run, tmp_path):
        out = tmp_path / "out"
        shutil.copytree(local_run.layout.root, out)
        options = dataclasses.replace(BATCH_OPTIONS, orders=tuple(range(1, 5)))
        with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None) as cluster, \
                distributed.Client(cluster) as client:
            result = run_batch(campaign[0], out, scheduler=client, options=options)
        assert result.resumed == 0
        assert all(r["order"] <= 4 for r in result.rows if r["status"] == "ok")


def _snapshot(folder) -> dict:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


class TestOutputFolder:
    def test_foreign_folder_refused_before_any_work(self, campaign, tmp_path):
        (tmp_path / "mine.txt").write_text("not a batch output")
        with pytest.raises(HelmetAncError, match="not empty and was not written by helmet-anc batch"):
            run_batch(campaign[0], tmp_path, workers=1, options=BATCH_OPTIONS)
        assert sorted(p.name for p in tmp_path.iterdir()) == ["mine.txt"]

    def test_every_output_is_recognisably_ours(self, local_run):
        layout = local_run.layout
        assert is_ours(layout.summary) and is_ours(layout.table_json) and is_ours(layout.marker)
        for sub in ("models", "results", "nominal"):
            assert all(is_ours(p) for p in (layout.root / sub).iterdir())

    @pytest.mark.parametrize("intruder", ["notes.txt", "models/H0_head9_fb.json", "results/extra.csv", "scratch"])
    def test_earlier_output_holding_foreign_files_refused_before_any_work(self, local_run, campaign, tmp_path, intruder):
        out = tmp_path / "out"
        shutil.copytree(local_run.layout.root, out)
        if intruder == "scratch":
            (out / intruder).mkdir()
        else:
            (out / intruder).write_text('{"mine": true}' if intruder.endswith(".json") else "mine")
        before = _snapshot(out)
        with pytest.raises(OutputRefused, match=f"did not write or that were edited since \\({intruder}\\)"):
            run_batch(campaign[0], out, workers=1, options=BATCH_OPTIONS)
        assert _snapshot(out) == before

    def test_model_edited_since_refused_and_force_writes_beside_it(self, local_run, campaign, tmp_path):
        out = tmp_path / "out"
        shutil.copytree(local_run.layout.root, out)
        model = out / "models" / "H0_head1_fb.json"
        model.write_text(model.read_text().replace('"path": "fb"', '"path": "fb", "note": "mine"'))
        with pytest.raises(OutputRefused, match="models/H0_head1_fb.json"):
            run_batch(campaign[0], out, workers=1, options=BATCH_OPTIONS)
        (out / "notes.txt").write_text("mine")
        forced = run_batch(campaign[0], out, workers=1, options=BATCH_OPTIONS, force=True)
        assert forced.resumed == 4  # nothing to redo: the inputs did not change
        assert (out / "notes.txt").read_text() == "mine" and '"note": "mine"' in model.read_text()

    def test_interrupted_writes_do_not_block_a_resume(self, local_run, campaign, tmp_path):
        # A worker killed inside an atomic write leaves its temporary file; the folder is still ours.
        out = tmp_path / "out"
        shutil.copytree(local_run.layout.root, out)
        (out / "models" / ".H0_head0_fb.json.k2j4x1.partial").write_text("{")
        (out / ".results.csv.9f3kq.partial").write_text("session,")
        assert run_batch(campaign[0], out, workers=1, options=BATCH_OPTIONS).resumed == 4


class TestRefine:
    def test_refine_runs_diagnosis_after_identification(self, campaign, tmp_path):
        from batch import read_sessions

        entries = read_sessions(campaign[0])[:1]
        result = run_batch(entries, tmp_path / "out", workers=1, refine=True, options=BATCH_OPTIONS)
        (row,) = result.rows
        assert row["status"] == "ok", row["reason"]
        assert row["seconds_refine"] > 0 and row["refine_steps"] == len([f for f in row["findings"].split(";") if f])
