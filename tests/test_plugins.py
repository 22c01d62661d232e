"""A detector written outside the package: the worked example ``examples/fdi-sim-cusum`` installed as
a distribution, found through its entry point, listed by ``fdi-sim plugins``, flown in the loop,
replayed bit for bit, run offline by ``fdi-sim detect`` and in a short study; broken plugins are
refused with their reason.

The package is installed with pip (its real build backend, ``--no-build-isolation`` so no
download is needed) into a folder of the test session that the subprocesses put on
``PYTHONPATH``: the entry point is then found exactly as in a site-packages, and the project's
venv, which the other test files share under pytest-xdist, never sees it.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "fdi-sim-cusum"
PLUGIN = "cusum-residual-v1"


def _env(site: Path) -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(site), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    return env


def _py(site: Path, code: str, timeout: float = 600) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code], env=_env(site), capture_output=True, text=True,
                          timeout=timeout, cwd=ROOT)


def _cli(site: Path, *args: str, timeout: float = 900) -> subprocess.CompletedProcess:
    return _py(site, f"import sys; from fdi_sim.cli import main; sys.exit(main({list(args)!r}))", timeout)


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    target = tmp_path_factory.mktemp("plugin-site")
    r = subprocess.run([sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--no-build-isolation",
                        "--target", str(target), str(EXAMPLE)], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    assert list(target.glob("fdi_sim_cusum-*.dist-info/entry_points.txt"))
    return target


def test_the_example_package_passes_its_own_tests(site):
    r = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", str(EXAMPLE / "tests")],
                       env=_env(site), capture_output=True, text=True, timeout=900, cwd=EXAMPLE)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-2000:]


def test_fdi_sim_plugins_lists_it(site):
    r = _cli(site, "plugins")
    assert r.returncode == 0, r.stderr
    line = next(ln for ln in r.stdout.splitlines() if ln.strip().startswith(PLUGIN))
    assert "CUSUM" in line and "[plugin: fdi-sim-cusum 0.1.0]" in line


@pytest.fixture(scope="module")
def flown(site, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("plugin-run")
    text = (ROOT / "scenarios" / "f16_pitch_gyro_bias.toml").read_text()
    text = text.replace('turbulence = "light"', 'turbulence = "moderate"')
    text = text.replace('bank = "default"', 'bank = "none"\ncalibration_flights = 4\ncalibration_duration_s = 60.0')
    text += f'\n[[detectors]]\ntype = "{PLUGIN}"\nsignal = "q_radps"\n\n[[detectors]]\ntype = "kinematic-attitude-v1"\n'
    scn = out / "plugin.toml"
    scn.write_text(text)
    r = _cli(site, "run", str(scn), "--log", str(out / "plugin.mcap"), "--duration", "40", "--quiet")
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-3000:]
    assert f"fdi bank   {PLUGIN}, kinematic-attitude-v1" in r.stdout
    return out / "plugin.mcap"


def test_the_plugin_flies_in_the_loop_and_replays_bit_for_bit(site, flown):
    from fdi_sim.flightlog import read_log

    log = read_log(flown)
    members = json.loads(log.metadata["fdi"]["members"])
    assert [m["id"] for m in members] == [PLUGIN, "kinematic-attitude-v1"]
    assert members[0]["hypotheses"] == ["q_radps"]
    notes = json.loads(log.metadata["fdi"]["notes"])
    assert any("plugin from fdi-sim-cusum" in n for n in notes)
    st = log.topics[f"/fdi/{PLUGIN}/statistic"]
    assert len(st.t_s) == 800 and f"/fdi/{PLUGIN}/residual" in log.topics
    cal = json.loads(log.metadata["fdi"]["calibration"])
    assert cal["members"][0]["id"] == PLUGIN and cal["members"][0]["threshold"] > 0  # the bank's one rule
    r = _cli(site, "detect", str(flown), "--bank", "scenario")
    assert r.returncode == 0, r.stderr[-3000:]
    assert f"identical to the log's /fdi/{PLUGIN}/statistic" in r.stdout


def test_a_plugin_option_its_factory_refuses_is_bad_input(site, tmp_path):
    scn = tmp_path / "s.toml"
    scn.write_text((ROOT / "scenarios" / "f16_cruise_doublets.toml").read_text()
                   + f'\n[[detectors]]\ntype = "{PLUGIN}"\nsignal = "q_rad_s"\n')
    r = _cli(site, "run", str(scn), "--out", str(tmp_path), "--duration", "3", "--quiet")
    assert r.returncode == 2, r.stderr[-2000:]
    assert "detectors[0]" in r.stderr and "q_rad_s" in r.stderr and "Traceback" not in r.stderr


def test_fdi_sim_detect_runs_the_plugin_offline(site, flown):
    r = _cli(site, "detect", str(flown), "--detector", f"{PLUGIN}:signal=q_radps", "--json")
    assert r.returncode == 0, r.stderr[-3000:]
    rep = json.loads(r.stdout)
    (d,) = rep["detectors"]
    assert d["id"] == PLUGIN and d["samples"] > 700 and not d["error"]


def test_the_plugin_flies_in_a_short_study(site, tmp_path):
    base = (ROOT / "scenarios" / "f16_cruise_doublets.toml").read_text()
    (tmp_path / "plugin_base.toml").write_text(base + f'\n[[detectors]]\ntype = "{PLUGIN}"\nsignal = "p_radps"\n')
    study = tmp_path / "study.toml"
    study.write_text('''kind = "study"
name = "plugin_study"
scenario = "plugin_base.toml"
seed = 7700
runs = 2
duration_s = 30.0

[bank]
bank = "none"
calibration_flights = 3
calibration_duration_s = 60.0
''')
    r = _cli(site, "study", str(study), "--out", str(tmp_path / "out"), "--workers", "1", "--no-report", "--json",
             "--quiet")
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-3000:]
    s = json.loads(r.stdout)
    assert s["runs"] == 2 and [d["id"] for d in s["detectors"]] == [PLUGIN]


def test_a_broken_plugin_is_refused_with_its_reason(tmp_path):
    """Three installed distributions whose entry points cannot be used: an import error, an id
    that is not versioned, an id that is already a built-in's; fdi-sim still starts and says why."""
    site = tmp_path / "site"
    site.mkdir()
    (site / "bad_plugin.py").write_text("import not_a_module_anywhere\n")
    (site / "ok_plugin.py").write_text("def make(model, **kw):\n    '''A factory.'''\n    return None\n")
    dist = site / "bad_plugins-1.0.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: bad-plugins\nVersion: 1.0\n")
    (site / "exit_plugin.py").write_text("import sys\nsys.exit('argparse said no')\n")
    (site / "selfreg_plugin.py").write_text(
        "from fdi_sim.registry import register\n"
        "def make(model, **kw):\n    return None\n"
        "make.__doc__ = 3  # not a string\n"
        "register('detector', 'selfreg-v1', 'registers itself', make)\n")
    (dist / "entry_points.txt").write_text("[fdi_sim.detectors]\nbroken-import-v1 = bad_plugin:make\n"
                                           "NotVersioned = ok_plugin:make\nparity-v1 = ok_plugin:make\n"
                                           "exits-v1 = exit_plugin:make\nselfreg-v1 = selfreg_plugin:make\n")
    r = _cli(site, "plugins")
    assert r.returncode == 0, r.stderr
    out = r.stdout
    assert "[refused plugins]" in out
    assert "broken-import-v1" in out and "ModuleNotFoundError" in out
    assert "NotVersioned" in out and "must look like 'name-v1'" in out
    assert "'parity-v1' is already registered by fdi-sim" in out
    assert "exits-v1" in out and "SystemExit: argparse said no" in out
    # a module that registers itself while imported is recorded with its distribution, never as a built-in
    line = next(ln for ln in out.splitlines() if ln.strip().startswith("selfreg-v1"))
    assert "[plugin: bad-plugins 1.0]" in line
    scn = tmp_path / "s.toml"
    scn.write_text((ROOT / "scenarios" / "f16_cruise_doublets.toml").read_text()
                   + '\n[[detectors]]\ntype = "broken-import-v1"\n')
    r = _cli(site, "run", str(scn), "--out", str(tmp_path), "--duration", "3", "--quiet")
    assert r.returncode == 2 and "broken-import-v1" in r.stderr and "was refused" in r.stderr, r.stderr


def test_a_plugin_that_fails_its_contract_is_refused_before_it_flies(tmp_path):
    site = tmp_path / "site"
    site.mkdir()
    (site / "leaky_plugin.py").write_text('''
import numpy as np


class Leaky:
    """Its statistic depends on how the samples are cut into blocks."""
    hypotheses = ()
    estimate_names = ()
    independent = False
    fault_directions = False
    residual_names = ("e",)

    def __init__(self, model):
        self.id = "leaky-v1"
        self.input_names = ()
        self.output_names = ("q_radps",)
        self._thr = 1.0

    @property
    def threshold(self):
        return self._thr

    def set_threshold(self, v):
        self._thr = float(v)

    def reset(self):
        pass

    def start_at(self, h_ft, vc_kts):
        pass

    def design_key(self):
        return b"leaky"

    def process_block(self, t_s, u, y, ok, fresh, out):
        e = y[:, 0] - y[:, 0].mean()
        out.statistic[:] = np.abs(e)
        out.valid[:] = True
        out.threshold[:] = self._thr
        out.hypothesis[:] = -1
        out.residual[:, 0] = e


def make(model, **options):
    """A plugin whose statistic depends on the block size."""
    return Leaky(model)
''')
    dist = site / "leaky_plugin-1.0.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: leaky-plugin\nVersion: 1.0\n")
    (dist / "entry_points.txt").write_text("[fdi_sim.detectors]\nleaky-v1 = leaky_plugin:make\n")
    scn = tmp_path / "s.toml"
    scn.write_text((ROOT / "scenarios" / "f16_cruise_doublets.toml").read_text()
                   + '\n[fdi]\ncalibration_flights = 2\ncalibration_duration_s = 20.0\n[[detectors]]\ntype = "leaky-v1"\n')
    r = _cli(site, "run", str(scn), "--out", str(tmp_path), "--duration", "3", "--quiet")
    assert r.returncode == 2, r.stdout + r.stderr
    assert "leaky-v1" in r.stderr and "fails its contract check" in r.stderr and "blocks of 1 differ" in r.stderr
    assert not list(tmp_path.glob("*.mcap"))
