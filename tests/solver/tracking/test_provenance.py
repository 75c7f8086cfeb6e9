"""The tracked bundle's provenance (solver.tracking.provenance): the model digest is the same for the same
model built twice and changes with a 1e-9 m move of one vertex; the record keeps what merge-tracks checks."""
from articula.sample_scenes import synthetic
from articula.solver.tracking.provenance import SOURCE, model_digest, track_provenance


def test_model_digest_changes_with_any_array():
    model = synthetic.tube_body(rings=4, segments=6)
    d = model_digest(model)
    assert d == model_digest(synthetic.tube_body(rings=4, segments=6))
    moved = synthetic.tube_body(rings=4, segments=6)
    moved.rest_vertices[3, 1] += 1e-9
    assert model_digest(moved) != d


def test_the_record_drops_the_frame_range_and_keeps_the_report():
    prov = track_provenance("abc", "scans", 30, 6, ["a", "b"], {"frames": [6, 8], "adapt": "off"}, False, {"x": 1})
    assert prov == {"source": SOURCE, "model_sha256": "abc", "input": {"source": "scans", "frames": 30},
                    "first_frame": 6, "frame_names": ["a", "b"], "options": {"adapt": "off"}, "adapted": False,
                    "report": {"x": 1}}
    assert "report" not in track_provenance("abc", "scans", 30, 6, [], {}, True)
