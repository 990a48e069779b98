"""core.execution.cost prices every setting that changes a bake's work (the maps baked, Denoise) and
the machine's load, as the panel's estimate shows it before the click; bench.sections.estimate
measures it against real bakes of each setting."""

import pytest

from core.execution import cost


def seconds(**kw):
    args = dict(covered_texels=100_000, samples=64, triangles=30_000, threads=2, processes=1)
    args.update(kw)
    return cost.estimate(**args).seconds


def test_two_maps_cost_twice_the_rays_and_texels_of_one():
    one, two = seconds(), seconds(quantities=2)
    per_map = (cost.NS_PER_RAY * 100_000 * 64 + cost.NS_PER_TEXEL * 100_000) * 1e-9 / 2 / cost.PARALLEL_EFFICIENCY
    assert two - one == pytest.approx(per_map)  # the triangles and the fixed share are paid once


def test_denoise_costs_by_the_covered_texels():
    plain, denoised = seconds(), seconds(denoise=True)
    assert denoised - plain == pytest.approx(cost.NS_PER_DENOISED_TEXEL * 1e-9 * 100_000 / 2 / cost.PARALLEL_EFFICIENCY)
    assert seconds(denoise=True, quantities=2) - seconds(quantities=2) == pytest.approx(2 * (denoised - plain))


@pytest.mark.parametrize("threads, load, cpus, cores", [
    (2, None, None, 2),          # nothing known: what the bake asks for
    (2, 0.0, 2, 2),              # an idle machine
    (2, 14.0, 2, 0.25),          # 14 runnable threads on 2 cores: 2 of 16 threads' share
    (1, 1.0, 2, 1),              # room for it
    (16, 2.0, 4, 64 / 18),       # 16 of the 18 runnable threads' share of 4 cores
    (8, 0.0, 4, 4),              # never more than the machine has
])
def test_the_bake_gets_its_share_of_a_busy_machine(threads, load, cpus, cores):
    assert cost.cores_of(threads, load, cpus) == pytest.approx(cores)


def test_a_loaded_machine_makes_the_bake_longer_not_the_memory_larger():
    idle = cost.estimate(100_000, 64, 30_000, threads=2, load=0.0, cpus=2)
    busy = cost.estimate(100_000, 64, 30_000, threads=2, load=14.0, cpus=2)
    assert busy.seconds == pytest.approx(8 * idle.seconds) and busy.bytes == idle.bytes


def test_the_machines_load_is_read_where_the_system_has_it():
    load, cpus = cost.machine_load()
    assert (load is None and cpus is None) or (load >= 0 and cpus >= 1)


def test_starting_worker_processes_is_priced_once():
    warm = cost.estimate(100_000, 64, 30_000, threads=1, processes=2)
    cold = cost.estimate(100_000, 64, 30_000, threads=1, processes=2, starting=2)
    assert cold.seconds - warm.seconds == pytest.approx(cost.WORKER_START_SECONDS)  # two side by side
