"""``./run farm track`` before it reaches a Manager (no Flamenco needed): a chunk size given alone picks
an overlap that fits and says which; the plan it prints is the one submitted."""
import pytest

from articula.sample_scenes.depth_bench import bench_recording

pytestmark = pytest.mark.usefixtures("cache_home")

NOBODY = "http://127.0.0.1:9"            # the discard port: nothing listens there


@pytest.fixture(scope="module")
def bench(tmp_path_factory):
    return bench_recording(tmp_path_factory.mktemp("depth") / "rec", subject_seed=0, resolution=(160, 120), frames=6)


def test_chunk_without_overlap_picks_one_that_fits(pkg, bench, tmp_path, capsys):
    code = pkg("addon.cli.main").main(["farm", "track", "--manager", NOBODY, "--model", bench["model_path"],
                                       "--depth", bench["out_dir"], "--out", str(tmp_path / "t.npz"),
                                       "--chunk", "2"])
    out, err = capsys.readouterr()
    assert code == 2 and "unreachable" in err, err              # refused only for the Manager nobody runs
    assert "overlap 1 frames (chunk 2" in out and "3 chunks: 0:2, 1:4, 3:6" in out, out
    assert not list(tmp_path.iterdir())
