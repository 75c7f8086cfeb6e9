"""Set-up step of ./run: make sure the MakeHuman sample assets are downloaded and verified."""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from sample_scenes.assets import ensure_assets  # noqa: E402

if __name__ == "__main__":
    ensure_assets()
