"""Weight-step problems shared by the tests of solver.learn.weights: binary start weights on the tube body."""
import numpy as np

from articula.solver.geometry.mesh_graph import uniform_laplacian
from articula.solver.learn.objective import RigObjective
from articula.solver.rig.model import Model

from articula.sample_scenes.tube_scans import body, hybrid_truth


def binary_start(model):
    _, _, labels = body()
    V, B = model.num_vertices, model.skeleton.num_bones
    return Model(model.rest_vertices, model.faces, model.skeleton, labels.astype(np.int32),
                 np.zeros((V, B), np.float32), np.zeros((V, B), np.float32))


def noisy_problem(M=5, seed=3):
    model, poses, scans = hybrid_truth(M)
    noisy = scans + 0.002 * np.random.default_rng(seed).normal(size=scans.shape)
    return binary_start(model), poses, RigObjective(noisy, uniform_laplacian(model.faces, model.num_vertices), 100.0)
