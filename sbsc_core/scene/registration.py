"""Fine registration of the scanner stations before anything else is measured.

The scans come registered (contract 1), but a target-based registration leaves each
station off by a few millimetres and a few thousandths of a degree. Every surface is then
a blend of slightly shifted copies, and an object is placed where the stations that saw it
put it: at 5 mm pixels that error is as large as the method's own. When the stations come
as separate files (one file per station, as scanners write them), their overlaps say how
they disagree, and this stage removes the disagreement, in the spirit of the multiway
registration of Choi et al. (2015) that Open3D implements:

1. :func:`station_cloud` thins each file's share of the sample (the regular sample that
   segmentation runs on) to one point per voxel and estimates its normals;
2. :func:`pair_edges` aligns every two stations that overlap with point-to-plane ICP
   (robust Tukey loss) started at the given registration, and keeps the motion and its
   information matrix (:func:`plane_information`: the point-to-plane normal equations) when
   the pair is close enough to be the same surfaces;
3. :func:`station_poses` solves the pose graph of each connected group of stations
   (Levenberg-Marquardt over all pairs at once, Open3D's ``global_optimization``), then
   moves the whole group by the one rigid motion that brings it back onto the given
   registration in the least-squares sense (:func:`least_change`): the given registration
   is trusted on average, only the stations' disagreement is removed.

A station whose refined pose moves any of its points more than ``max_shift_m`` keeps the
given registration (the refinement is for small errors only); so does every station
when there is one file, and when the stations already agree: when the median over the
overlapping pairs of how far ICP moves a pair's points on average is at most
``min_disagreement_m``, the given registration agrees within the method's own precision
and refining it would only add that noise (on a simulated storey of 29 perfectly
registered station files the median was 0.38 mm, and refining moved the stations' points
by up to 1.3 mm on average, which gave a spurious wall; with the realistic scanner's 2 mm
registration error it is 3.8 mm). Open3D does the ICP, the information matrices, the pose-graph
optimisation and the least-squares rigid fit: nothing of it is written here.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from ..settings import RegistrationSettings

__all__ = ["StationSamples", "station_points", "station_sample_points", "StationEdge", "Registration",
           "station_cloud", "pair_edges", "station_poses", "least_change", "plane_information",
           "refine_registration"]


class StationSamples:
    """The points of each station (file) kept from the sample while it is read.

    :meth:`add` keeps at most ``budget`` points of a station in all (a regular stride of
    each piece it is given, so a station read in several parts keeps a share of each).
    """

    def __init__(self, n_stations: int, budget: int, pieces: Sequence[int]) -> None:
        self.budget = budget
        self.pieces = list(pieces)  # parts per station, to share the budget between them
        self.points: list[list[np.ndarray]] = [[] for _ in range(n_stations)]

    def add(self, station: int, xyz: np.ndarray) -> None:
        """Keep a regular share of ``xyz`` (points of ``station``, float32, recentred)."""
        share = max(1, self.budget // max(1, self.pieces[station]))
        step = max(1, math.ceil(len(xyz) / share))
        self.points[station].append(np.array(xyz[::step], np.float32))

    def station(self, k: int) -> np.ndarray:
        """All points kept of station ``k``, (n, 3) float32."""
        got = self.points[k]
        return np.concatenate(got) if got else np.zeros((0, 3), np.float32)


@dataclass(frozen=True)
class StationEdge:
    """Two stations that overlap: ``transformation`` moves ``source`` onto ``target``."""

    source: int
    target: int
    transformation: np.ndarray  # (4, 4)
    information: np.ndarray  # (6, 6)
    fitness: float  # share of the source's points with a partner in the target
    rmse_m: float  # RMS distance of the partners after ICP


@dataclass
class Registration:
    """What :func:`refine_registration` found: one 4x4 pose per station (identity: as given)."""

    poses: list[np.ndarray]
    edges: list[StationEdge]
    kept_as_given: list[int]  # stations whose refinement was refused (moved too far)
    # (all of them when the stations already agreed within ``min_disagreement_m``)
    groups: list[list[int]]  # connected groups of stations (by overlap)

    def records(self, names: Sequence[str]) -> list[dict]:
        """Per station: its name (``file``), how far its points were moved (translation at the
        scan's recentring ``origin``, metres) and turned (degrees), and the whole ``pose`` (4x4
        rows, applied to points relative to that origin); for the detections document."""
        out = []
        for name, pose in zip(names, self.poses, strict=True):
            angle = math.degrees(math.acos(max(-1.0, min(1.0, (float(np.trace(pose[:3, :3])) - 1) / 2))))
            out.append({"file": name, "translation_m": [round(float(x), 5) for x in pose[:3, 3]],
                        "rotation_deg": round(angle, 5),
                        "pose": [[round(float(x), 9) for x in row] for row in pose]})
        return out


def station_points(n_stations: int, settings: RegistrationSettings) -> int:
    """Points kept of each of ``n_stations`` stations: ``max_points``, fewer when there are so
    many stations that all together would pass ``max_total_points`` (never under 2,000)."""
    return max(2_000, min(settings.max_points, settings.max_total_points // max(1, n_stations)))


def station_sample_points(n_stations: int, settings: RegistrationSettings) -> int:
    """Points of each station's share of the sample kept while it is read: ``sample_points``,
    fewer when all together would pass four times ``max_total_points`` (bounded memory)."""
    return max(4 * 2_000, min(settings.sample_points, 4 * settings.max_total_points // max(1, n_stations)))


def station_cloud(xyz: np.ndarray, *, voxel_m: float, max_points: int):
    """One station's points as an Open3D cloud for ICP: one point per ``voxel_m`` voxel, at
    most ``max_points`` (a regular stride of the voxels), with normals from their neighbours.

    Returns None when fewer than 100 points are left.
    """
    import open3d as o3d

    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.asarray(xyz, np.float64)))
    pcd = pcd.voxel_down_sample(voxel_m)
    n = len(pcd.points)
    if n > max_points:
        pcd = pcd.select_by_index(np.arange(0, n, math.ceil(n / max_points)).tolist())
    if len(pcd.points) < 100:
        return None
    pcd.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=4 * voxel_m, max_nn=20))
    return pcd


def _cells(cloud, size: float) -> np.ndarray:
    """The cells of a ``size`` grid that ``cloud`` occupies, as sorted unique int64 keys."""
    q = np.floor(np.asarray(cloud.points) / size).astype(np.int64) + (1 << 20)
    return np.unique((q[:, 0] << 42) | (q[:, 1] << 21) | q[:, 2])


def _boxes_meet(a, b, margin: float) -> bool:
    lo_a, hi_a = np.asarray(a.get_min_bound()), np.asarray(a.get_max_bound())
    lo_b, hi_b = np.asarray(b.get_min_bound()), np.asarray(b.get_max_bound())
    return bool(np.all(lo_a - margin <= hi_b) and np.all(lo_b - margin <= hi_a))


def pair_edges(clouds: Sequence, *, settings: RegistrationSettings) -> list[StationEdge]:
    """Every pair of stations that overlap, aligned by point-to-plane ICP (Open3D).

    A pair is tried when at least ``min_overlap`` of the smaller cloud's cells (a grid of
    ``max_distance_m``) are occupied by the other too. ICP pairs each point with the nearest
    point of the other cloud within ``max_distance_m`` (the clouds are thinned to a few
    points per cell), and its robust (Tukey) loss ignores pairs farther than
    ``plane_tolerance_m`` from each other's plane: another surface, not a misregistration.
    The pair is kept when at least ``min_overlap`` of the smaller cloud's points end within
    that tolerance and ICP moves them by at most ``max_shift_m``. The smaller cloud is the
    source, so ``fitness`` is the share of the smaller one.
    """
    import open3d as o3d

    reg = o3d.pipelines.registration
    d = settings.max_distance_m
    method = reg.TransformationEstimationPointToPlane(reg.TukeyLoss(k=settings.plane_tolerance_m))
    criteria = reg.ICPConvergenceCriteria(relative_fitness=1e-7, relative_rmse=1e-7, max_iteration=40)
    eye = np.eye(4)
    edges: list[StationEdge] = []
    trees: dict[int, cKDTree] = {}
    cells = [None if c is None else _cells(c, d) for c in clouds]
    for i in range(len(clouds)):
        for j in range(i + 1, len(clouds)):
            a, b = clouds[i], clouds[j]
            if a is None or b is None or not _boxes_meet(a, b, d):
                continue
            shared = len(np.intersect1d(cells[i], cells[j], assume_unique=True))
            if shared < settings.min_overlap * min(len(cells[i]), len(cells[j])):
                continue
            s, t = (i, j) if len(a.points) <= len(b.points) else (j, i)
            src, tgt = clouds[s], clouds[t]
            icp = reg.registration_icp(src, tgt, d, eye, method, criteria)
            T = np.asarray(icp.transformation)
            if _largest_move(T, src) > settings.max_shift_m:
                continue
            if t not in trees:
                trees[t] = cKDTree(np.asarray(tgt.points))
            info, paired = plane_information(src, tgt, T, max_distance_m=d, tolerance_m=settings.plane_tolerance_m,
                                             tree=trees[t])
            fitness = paired / len(src.points)
            if fitness >= settings.min_overlap:
                edges.append(StationEdge(s, t, T, info, fitness, float(icp.inlier_rmse)))
    return edges


def plane_information(source, target, transformation: np.ndarray, *, max_distance_m: float, tolerance_m: float,
                      tree: cKDTree | None = None) -> tuple[np.ndarray, int]:
    """The information matrix (6x6, rotation then translation, as Open3D's pose graph takes
    it) of point-to-plane distances between ``source`` moved by ``transformation`` and
    ``target``, and the number of pairs it sums: ``J^T J`` with ``J = [p x n, n]`` over the
    nearest pairs closer than ``max_distance_m`` and within ``tolerance_m`` of the target's
    plane.

    Open3D's ``get_information_matrix_from_point_clouds`` is that of point-to-point
    distances, which says a pair is as sure along a corridor as across it; this one is zero
    along a direction in which the two overlap only in planes parallel to it, so the pose
    graph takes that direction from the other pairs (hence written here).
    """
    p = np.asarray(source.points) @ transformation[:3, :3].T + transformation[:3, 3]
    tree = tree if tree is not None else cKDTree(np.asarray(target.points))
    dist, idx = tree.query(p, distance_upper_bound=max_distance_m)
    ok = np.flatnonzero(np.isfinite(dist))
    n = np.asarray(target.normals)[idx[ok]]
    q = np.asarray(target.points)[idx[ok]]
    near = np.abs(np.einsum("ij,ij->i", p[ok] - q, n)) <= tolerance_m
    p, n = p[ok][near], n[near]
    J = np.concatenate([np.cross(p, n), n], axis=1)
    return J.T @ J, int(near.sum())


def _largest_move(T: np.ndarray, cloud) -> float:
    """How far ``T`` moves the farthest corner of ``cloud``'s bounding box (metres)."""
    lo, hi = np.asarray(cloud.get_min_bound()), np.asarray(cloud.get_max_bound())
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    moved = corners @ T[:3, :3].T + T[:3, 3]
    return float(np.max(np.linalg.norm(moved - corners, axis=1)))


def _mean_move(T: np.ndarray, cloud) -> float:
    """How far ``T`` moves ``cloud``'s points on average (metres)."""
    p = np.asarray(cloud.points)
    return float(np.mean(np.linalg.norm(p @ T[:3, :3].T + T[:3, 3] - p, axis=1)))


def _disagreement(edges: Sequence[StationEdge], clouds: Sequence) -> float:
    """How much the overlapping stations disagree: the median over the pairs of how far each
    pair's ICP moves its source's points on average (metres)."""
    return float(np.median([_mean_move(e.transformation, clouds[e.source]) for e in edges]))


def _groups(n: int, edges: Sequence[StationEdge]) -> list[list[int]]:
    """Connected groups of stations (by the edges), each sorted, in order of first station."""
    parent = list(range(n))

    def root(k: int) -> int:
        while parent[k] != k:
            parent[k] = parent[parent[k]]
            k = parent[k]
        return k

    for e in edges:
        parent[root(e.source)] = root(e.target)
    groups: dict[int, list[int]] = {}
    for k in range(n):
        groups.setdefault(root(k), []).append(k)
    return sorted(groups.values(), key=lambda g: g[0])


def least_change(clouds: Sequence, poses: Sequence[np.ndarray]) -> np.ndarray:
    """The rigid motion that brings the refined stations back onto the given registration
    as a whole: least squares over every station's points between where the poses put them
    and where they were given (Open3D's point-to-point estimation, i.e. Horn's / Umeyama's
    closed form)."""
    import open3d as o3d

    given = np.concatenate([np.asarray(c.points) for c in clouds])
    moved = np.concatenate([np.asarray(c.points) @ P[:3, :3].T + P[:3, 3] for c, P in zip(clouds, poses, strict=True)])
    corres = np.repeat(np.arange(len(given), dtype=np.int32)[:, None], 2, axis=1)
    est = o3d.pipelines.registration.TransformationEstimationPointToPoint()
    return np.asarray(est.compute_transformation(o3d.geometry.PointCloud(o3d.utility.Vector3dVector(moved)),
                                                 o3d.geometry.PointCloud(o3d.utility.Vector3dVector(given)),
                                                 o3d.utility.Vector2iVector(corres)))


def station_poses(clouds: Sequence, edges: Sequence[StationEdge], *, settings: RegistrationSettings
                  ) -> tuple[list[np.ndarray], list[list[int]]]:
    """A pose per station from the pairs: each connected group's pose graph optimised at once
    (Open3D's Levenberg-Marquardt ``global_optimization``), then moved as a whole by
    :func:`least_change`. A station alone keeps the identity."""
    import open3d as o3d

    reg = o3d.pipelines.registration
    poses = [np.eye(4) for _ in clouds]
    groups = _groups(len(clouds), edges)
    for group in groups:
        if len(group) < 2:
            continue
        local = {k: n for n, k in enumerate(group)}
        graph = reg.PoseGraph()
        for _ in group:
            graph.nodes.append(reg.PoseGraphNode(np.eye(4)))
        for e in edges:
            if e.source in local:
                graph.edges.append(reg.PoseGraphEdge(local[e.source], local[e.target], e.transformation,
                                                     e.information, uncertain=False))
        option = reg.GlobalOptimizationOption(max_correspondence_distance=settings.max_distance_m,
                                              edge_prune_threshold=0.25, reference_node=0)
        with o3d.utility.VerbosityContextManager(o3d.utility.VerbosityLevel.Error):
            reg.global_optimization(graph, reg.GlobalOptimizationLevenbergMarquardt(),
                                    reg.GlobalOptimizationConvergenceCriteria(), option)
        found = [np.asarray(graph.nodes[local[k]].pose) for k in group]
        back = least_change([clouds[k] for k in group], found)
        for k, P in zip(group, found, strict=True):
            poses[k] = back @ P
    return poses, groups


def refine_registration(samples: Sequence[np.ndarray], *, settings: RegistrationSettings,
                        log: Callable[[str], None] | None = None) -> Registration:
    """Refined poses of the stations (4x4, applied to each station's recentred points).

    Parameters
    ----------
    samples : sequence of (n, 3) float arrays
        Each station's sampled points in the common (recentred) frame, as registered.
    settings : RegistrationSettings
        Voxel size, point budget, pairing distance and the largest move accepted.
    log : callable, optional
        Receives one line per refused station.

    Returns
    -------
    Registration
        One pose per station (the identity for a station kept as given), the pairs used and
        the connected groups.
    """
    say = log or (lambda msg: None)
    each = station_points(len(samples), settings)
    clouds = [station_cloud(x, voxel_m=settings.voxel_m, max_points=each) if len(x) else None for x in samples]
    usable = [k for k, c in enumerate(clouds) if c is not None]
    if len(usable) < 2:
        return Registration([np.eye(4) for _ in samples], [], [], [[k] for k in range(len(samples))])
    sub = [clouds[k] for k in usable]
    edges = pair_edges(sub, settings=settings)
    poses = [np.eye(4) for _ in samples]
    refused: list[int] = []
    if edges and _disagreement(edges, sub) <= settings.min_disagreement_m:
        say(f"the stations agree within {settings.min_disagreement_m * 1000:.1f} mm: kept as registered")
        groups = _groups(len(sub), edges)
        refused = list(usable)
    else:
        found, groups = station_poses(sub, edges, settings=settings)
        for n, k in enumerate(usable):
            if _largest_move(found[n], sub[n]) > settings.max_shift_m:
                refused.append(k)
                say(f"station {k + 1}: its refined pose moves it more than {settings.max_shift_m * 1000:.0f} mm; "
                    "kept as registered")
                continue
            poses[k] = found[n]
    edges = [StationEdge(usable[e.source], usable[e.target], e.transformation, e.information, e.fitness, e.rmse_m)
             for e in edges]
    return Registration(poses, edges, refused, [[usable[n] for n in g] for g in groups]
                        + [[k] for k in range(len(samples)) if clouds[k] is None])


