"""Running generated code on the host (codegen.build): cached cffi builds and the runners targets name."""

import numpy as np
import pytest
from conftest_codegen import appendix_a_model

from codegen.api import generate_firmware
from codegen.build import HOST_RUNNERS, CmsisPackageFilter, HostFilter, build_host, cache_dir, host_filter
from codegen.errors import BuildError, VerificationError
from codegen.manifest import Manifest
from codegen.plan import plan_firmware
from codegen.reference import fixed_reference, to_q15
from codegen.targets import TARGETS


def test_host_build_cached_by_source_hash(tmp_path):
    manifest = generate_firmware(appendix_a_model("ff"), tmp_path / "ff", variant="q15")
    header = (tmp_path / "ff" / "ff_filter.h").read_text()
    source = (tmp_path / "ff" / "ff_filter.c").read_text()
    build_host("ff", header, source)
    before = sorted(p.name for p in cache_dir().iterdir())
    host = build_host("ff", header, source)
    assert sorted(p.name for p in cache_dir().iterdir()) == before
    assert host.variants == ("q15",)
    assert isinstance(manifest, Manifest)


def test_every_target_names_a_runner():
    assert {target.host for target in TARGETS.values()} <= set(HOST_RUNNERS)


def test_cffi_runner_runs_the_rendered_code(tmp_path):
    generate_firmware(appendix_a_model("ff"), tmp_path / "ff", variant="q15")
    files = {name: (tmp_path / "ff" / name).read_text() for name in ("ff_filter.h", "ff_filter.c")}
    plan = plan_firmware(appendix_a_model("ff"), variant="q15")
    host = host_filter("cffi", "ff", files, plan.designs)
    assert isinstance(host, HostFilter)
    x = to_q15(0.3 * np.sin(np.arange(300) / 7.0))
    np.testing.assert_array_equal(host.process_q15(x), fixed_reference(plan.fixed, x))


def test_cmsisdsp_runner_takes_the_tables():
    plan = plan_firmware(appendix_a_model("ff"), target="cmsis", min_snr=0.0)
    try:
        host = host_filter("cmsisdsp", "ff", {}, plan.designs)
    except VerificationError as exc:  # the cmsisdsp package is not installed
        pytest.skip(str(exc))
    assert isinstance(host, CmsisPackageFilter)


def test_an_unknown_runner_is_refused():
    with pytest.raises(BuildError, match="host runner must be one of cffi, cmsisdsp; found 'qemu'"):
        host_filter("qemu", "ff", {}, {})
