// Bindings of calibproj::ba: numpy arrays in, a Result of numpy arrays out.

#include <pybind11/eigen.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <map>
#include <stdexcept>
#include <string>

#include "calibproj/ba/bundle_adjuster.h"
#include "calibproj/ba/manifolds.h"
#include "calibproj/ba/projector_cost.h"
#include "calibproj/ba/relief_cost.h"
#include "calibproj/ba/reprojection_cost.h"
#include "convert.h"
#include "registry.h"

namespace py = pybind11;

namespace calibproj::bindings {

namespace {

// Intrinsics from an array (C, 3, 3) of upper-triangular camera matrices.
std::vector<ba::Intrinsics> IntrinsicsFromArray(const py::array_t<double, py::array::c_style | py::array::forcecast>& K) {
  if (K.ndim() != 3 || K.shape(1) != 3 || K.shape(2) != 3) {
    throw std::invalid_argument("intrinsics: expected an array of shape (cameras, 3, 3)");
  }
  std::vector<ba::Intrinsics> out(K.shape(0));
  const auto k = K.unchecked<3>();
  for (py::ssize_t c = 0; c < K.shape(0); ++c) {
    out[c] = {k(c, 0, 0), k(c, 1, 1), k(c, 0, 2), k(c, 1, 2), k(c, 0, 1)};
  }
  return out;
}

Eigen::Vector2d Vec2(const Eigen::VectorXd& v, const std::string& what) {
  if (v.size() != 2) throw std::invalid_argument(what + ": expected 2 values");
  return v;
}

ba::Intrinsics IntrinsicsOf(const Eigen::Matrix3d& K) { return {K(0, 0), K(1, 1), K(0, 2), K(1, 2), K(0, 1)}; }

// Residual and the requested Jacobian blocks of one cost function at one point.
py::tuple EvaluateCost(const ceres::CostFunction& cost, const std::vector<Eigen::VectorXd>& blocks,
                       std::vector<bool> want) {
  const auto& sizes = cost.parameter_block_sizes();
  if (want.empty()) want.assign(sizes.size(), true);
  if (blocks.size() != sizes.size() || want.size() != sizes.size()) {
    throw std::invalid_argument("expected " + std::to_string(sizes.size()) + " parameter blocks and flags");
  }
  std::vector<const double*> parameters;
  std::vector<RowMatrix> jacobians;
  std::vector<double*> jacobian_ptrs;
  for (size_t b = 0; b < sizes.size(); ++b) {
    if (blocks[b].size() != sizes[b]) throw std::invalid_argument("parameter block " + std::to_string(b) + " has the wrong size");
    parameters.push_back(blocks[b].data());
    jacobians.emplace_back(RowMatrix::Zero(2, sizes[b]));
  }
  for (size_t b = 0; b < sizes.size(); ++b) jacobian_ptrs.push_back(want[b] ? jacobians[b].data() : nullptr);
  Eigen::Vector2d residual;
  const bool ok = cost.Evaluate(parameters.data(), residual.data(), jacobian_ptrs.data());
  py::list out_jacobians;
  for (size_t b = 0; b < sizes.size(); ++b) {
    if (want[b]) out_jacobians.append(jacobians[b]); else out_jacobians.append(py::none());
  }
  return py::make_tuple(ok, residual, out_jacobians);
}

// A relief of one cell [0, spacing]^2: bilinear for 4 nodes, cubic for 16.
ba::ReliefGrid OneCellGrid(double spacing, const Eigen::VectorXd& nodes) {
  if (!(spacing > 0.0) || (nodes.size() != 4 && nodes.size() != 16)) {
    throw std::invalid_argument("expected a positive spacing and 4 (bilinear) or 16 (cubic) nodes");
  }
  ba::ReliefGrid grid;
  grid.spacing = spacing;
  grid.cell_columns = grid.cell_rows = 1;
  grid.cubic = nodes.size() == 16;
  return grid;
}

// One parameter block of size 1 per node height.
void AppendNodeBlocks(const Eigen::VectorXd& nodes, std::vector<Eigen::VectorXd>* blocks) {
  for (Eigen::Index k = 0; k < nodes.size(); ++k) blocks->push_back(Eigen::VectorXd::Constant(1, nodes(k)));
}

ba::Result BundleAdjustPy(const Eigen::VectorXi& camera_index, const Eigen::VectorXi& point_index,
                        const RowMatrix& observed,
                        const py::array_t<double, py::array::c_style | py::array::forcecast>& intrinsics,
                        const RowMatrix& poses, const RowMatrix& points, const Eigen::VectorXd& plane,
                        const std::string& model, const std::string& loss, double loss_scale,
                        int max_iterations, double function_tolerance, double gradient_tolerance,
                        double parameter_tolerance, int num_threads, const std::string& linear_solver,
                        bool refine_poses, bool refine_points, int gauge_camera, int scale_camera,
                        bool compute_covariance, bool full_report, bool cache_rotations,
                        const Eigen::VectorXi& lens_block, const RowMatrix& lens_jacobians,
                        const RowMatrix& more_planes, const Eigen::VectorXi& point_plane,
                        const ba::CostFactory& make_cost) {
  ba::Options options;
  options.model = ParseModel(model);
  options.loss = ParseLoss(loss);
  options.linear_solver = ParseChoice<ba::LinearSolver>(
      "linear_solver", linear_solver,
      {{"auto", ba::LinearSolver::kAuto},
       {"dense_schur", ba::LinearSolver::kDenseSchur},
       {"sparse_schur", ba::LinearSolver::kSparseSchur},
       {"iterative_schur", ba::LinearSolver::kIterativeSchur},
       {"dense_qr", ba::LinearSolver::kDenseQr},
       {"sparse_normal_cholesky", ba::LinearSolver::kSparseNormalCholesky}});
  options.loss_scale_px = loss_scale;
  options.max_iterations = max_iterations;
  options.function_tolerance = function_tolerance;
  options.gradient_tolerance = gradient_tolerance;
  options.parameter_tolerance = parameter_tolerance;
  options.num_threads = num_threads;
  options.refine_poses = refine_poses;
  options.refine_points = refine_points;
  options.gauge_camera = gauge_camera;
  options.scale_camera = scale_camera;
  options.compute_covariance = compute_covariance;
  options.full_report = full_report;
  options.cache_rotations = cache_rotations;

  ba::Data data;
  data.camera_index = camera_index;
  data.point_index = point_index;
  data.observed = RowsOf<ba::PixelMatrix>(observed, 2, "observed");
  data.intrinsics = IntrinsicsFromArray(intrinsics);
  data.poses = RowsOf<ba::PoseMatrix>(poses, 6, "poses");
  data.points = RowsOf<ba::PointMatrix>(points, 3, "points");
  if (options.model == ba::Model::kCoplanar) {
    if (plane.size() != 4) throw std::invalid_argument("plane: expected 4 values [nx, ny, nz, d]");
    data.plane = plane;
    data.more_planes = RowsOf<ba::PlaneMatrix>(more_planes, 4, "more_planes");
    data.point_plane = point_plane;
  }
  data.lens_block = lens_block;
  data.lens_jacobians = RowsOf<ba::LensJacobianMatrix>(lens_jacobians, 2 * ba::kLensBlockSize, "lens_jacobians");

  ba::Result result;
  {
    py::gil_scoped_release release;
    result = ba::BundleAdjust(data, options, make_cost);
  }
  return result;
}

// (C, 6, 6) of the per-camera covariances, or None when none was computed.
py::object PoseCovariances(const ba::Result& r) {
  if (r.pose_covariances.empty()) return py::none();
  py::array_t<double> out({static_cast<py::ssize_t>(r.pose_covariances.size()), py::ssize_t{6}, py::ssize_t{6}});
  auto view = out.mutable_unchecked<3>();
  for (size_t c = 0; c < r.pose_covariances.size(); ++c) {
    for (int i = 0; i < 6; ++i) {
      for (int j = 0; j < 6; ++j) view(c, i, j) = r.pose_covariances[c](i, j);
    }
  }
  return std::move(out);
}

// A matrix, or None when it is empty (not computed).
py::object MatrixOrNone(const Eigen::MatrixXd& matrix) {
  return matrix.size() == 0 ? py::none() : py::cast(matrix);
}

// The Result class, once per process (the benchmark module shares it).
void RegisterResult(py::module_& m) {
  if (py::detail::get_type_info(typeid(ba::Result))) return;
  py::class_<ba::Result>(m, "Result", "A bundle adjustment's solution and figures; its arrays are copies.")
      .def_readonly("initial_cost", &ba::Result::initial_cost, "0.5 * sum of squared (robustified) residuals")
      .def_readonly("final_cost", &ba::Result::final_cost)
      .def_readonly("iterations", &ba::Result::iterations)
      .def_readonly("termination", &ba::Result::termination)
      .def_readonly("usable", &ba::Result::usable, "Ceres found the solution usable")
      .def_readonly("solve_time_s", &ba::Result::solve_time_s)
      .def_readonly("gauge_camera", &ba::Result::gauge_camera)
      .def_readonly("scale_camera", &ba::Result::scale_camera, "FREE with poses and points refined; -1 otherwise")
      .def_property_readonly(
          "poses", [](const ba::Result& r) { return RowMatrix(r.poses); }, "(C, 6) cam_from_world [angle-axis, t]")
      .def_property_readonly(
          "points", [](const ba::Result& r) { return RowMatrix(r.points); }, "(P, 3)")
      .def_property_readonly(
          "plane", [](const ba::Result& r) { return Eigen::VectorXd(r.plane); }, "[nx, ny, nz, d] (COPLANAR)")
      .def_property_readonly(
          "more_planes", [](const ba::Result& r) { return RowMatrix(r.more_planes); }, "(K, 4), refined (COPLANAR)")
      .def_property_readonly(
          "residuals", [](const ba::Result& r) { return RowMatrix(r.residuals); }, "(N, 2) projected minus observed, pixels")
      .def_property_readonly("pose_covariances", &PoseCovariances,
                             "(C, 6, 6) of [dtheta, dt] per camera, with compute_covariance; else None")
      .def_property_readonly(
          "pose_covariance", [](const ba::Result& r) { return MatrixOrNone(r.pose_covariance); },
          "(6C, 6C) joint covariance with the cross terms, with compute_covariance; else None")
      .def_readonly("covariance_time_s", &ba::Result::covariance_time_s)
      .def_readonly("covariance_failure", &ba::Result::covariance_failure,
                    "why the covariance was requested but not given; empty otherwise")
      .def_property_readonly(
          "lens_sensitivity", [](const ba::Result& r) { return MatrixOrNone(r.lens_sensitivity); },
          "(6C, 8L) d [dtheta, dt] / d lens, with compute_covariance and lens_block; else None")
      .def_readonly("report", &ba::Result::report, "Ceres' full report, with full_report");
}

// Plus, Minus and their Jacobians of a manifold at one point, for tests of its invariants.
struct ManifoldValues {
  Eigen::VectorXd plus;   // Plus(x, delta)
  Eigen::VectorXd minus;  // Minus(y, x)
  RowMatrix plus_jacobian, minus_jacobian;  // at x
};

ManifoldValues ManifoldFunctions(const ceres::Manifold& manifold, const Eigen::VectorXd& x, const Eigen::VectorXd& y,
                           const Eigen::VectorXd& delta) {
  const int ambient = manifold.AmbientSize();
  const int tangent = manifold.TangentSize();
  if (x.size() != ambient || y.size() != ambient || delta.size() != tangent) {
    throw std::invalid_argument("manifold: expected x, y of size " + std::to_string(ambient) + " and delta of size " +
                                std::to_string(tangent));
  }
  ManifoldValues out{Eigen::VectorXd(ambient), Eigen::VectorXd(tangent), RowMatrix(ambient, tangent),
                     RowMatrix(tangent, ambient)};
  manifold.Plus(x.data(), delta.data(), out.plus.data());
  manifold.Minus(y.data(), x.data(), out.minus.data());
  manifold.PlusJacobian(x.data(), out.plus_jacobian.data());
  manifold.MinusJacobian(x.data(), out.minus_jacobian.data());
  return out;
}

void RegisterManifoldValues(py::module_& m) {
  py::class_<ManifoldValues>(m, "ManifoldValues", "A manifold's Plus, Minus and their Jacobians at one point")
      .def_readonly("plus", &ManifoldValues::plus, "Plus(x, delta)")
      .def_readonly("minus", &ManifoldValues::minus, "Minus(y, x)")
      .def_readonly("plus_jacobian", &ManifoldValues::plus_jacobian, "d Plus(x, delta) / d delta at delta = 0")
      .def_readonly("minus_jacobian", &ManifoldValues::minus_jacobian, "d Minus(y, x) / d y at y = x");
}

}  // namespace

void def_bundle_adjust(py::module_& m, const char* name, const ba::CostFactory& make_cost) {
  RegisterResult(m);
  m.def(
      name,
      [make_cost](const Eigen::VectorXi& camera_index, const Eigen::VectorXi& point_index, const RowMatrix& observed,
                  const py::array_t<double, py::array::c_style | py::array::forcecast>& intrinsics,
                  const RowMatrix& poses, const RowMatrix& points, const Eigen::VectorXd& plane,
                  const std::string& model, const std::string& loss, double loss_scale, int max_iterations,
                  double function_tolerance, double gradient_tolerance, double parameter_tolerance,
                  int num_threads, const std::string& linear_solver, bool refine_poses, bool refine_points,
                  int gauge_camera, int scale_camera, bool compute_covariance, bool full_report,
                  bool cache_rotations, const RowMatrix& more_planes, const Eigen::VectorXi& point_plane,
                  const Eigen::VectorXi& lens_block, const RowMatrix& lens_jacobians) {
        return BundleAdjustPy(camera_index, point_index, observed, intrinsics, poses, points, plane, model, loss,
                              loss_scale, max_iterations, function_tolerance, gradient_tolerance,
                              parameter_tolerance, num_threads, linear_solver, refine_poses, refine_points,
                              gauge_camera, scale_camera, compute_covariance, full_report, cache_rotations,
                              lens_block, lens_jacobians, more_planes, point_plane, make_cost);
      },
      py::arg("camera_index"), py::arg("point_index"), py::arg("observed"), py::arg("intrinsics"), py::arg("poses"),
      py::arg("points"), py::arg("plane") = Eigen::VectorXd(), py::kw_only(), py::arg("model") = "free",
      py::arg("loss") = "none", py::arg("loss_scale") = 1.0, py::arg("max_iterations") = 100,
      py::arg("function_tolerance") = 1e-12, py::arg("gradient_tolerance") = 1e-14,
      py::arg("parameter_tolerance") = 1e-12, py::arg("num_threads") = 1, py::arg("linear_solver") = "auto",
      py::arg("refine_poses") = true, py::arg("refine_points") = true, py::arg("gauge_camera") = 0,
      py::arg("scale_camera") = -1, py::arg("compute_covariance") = false, py::arg("full_report") = false,
      py::arg("cache_rotations") = true, py::arg("more_planes") = RowMatrix(0, 4),
      py::arg("point_plane") = Eigen::VectorXi(), py::arg("lens_block") = Eigen::VectorXi(),
      py::arg("lens_jacobians") = RowMatrix(0, 16),
      R"doc(Bundle adjustment (Ceres).

Observations: camera_index (N,), point_index (N,), observed (N, 2) undistorted pixels.
intrinsics (C, 3, 3); poses (C, 6) cam_from_world [angle-axis, t]; points (P, 3);
plane [nx, ny, nz, d] with n . X = d (COPLANAR only); COPLANAR made piecewise planar:
more_planes (K, 4) and point_plane (P,) (0: plane, k: more_planes[k - 1], -1: a free
3D point; empty: all on plane). model: free | coplanar;
loss: none | huber | cauchy (scale in pixels); linear_solver: auto | dense_schur |
sparse_schur | iterative_schur | dense_qr | sparse_normal_cholesky. The gauge camera's
pose is held fixed, and the scale through the plane offset (COPLANAR) or the distance
to the scale camera (FREE; -1 picks the farthest). Returns a Result with the refined
poses, points, plane, more_planes, per-observation residuals (N, 2), costs, iterations, termination,
solve time and, if compute_covariance, pose_covariances (C, 6, 6) of [dtheta, dt], their
joint covariance pose_covariance (6C, 6C) with the cross terms, and covariance_time_s;
with lens_block (C,) (per camera its lens block, -1 none) and lens_jacobians (N, 16)
(per observation d residual / d its camera's lens [f, cx, cy, k1, k2, p1, p2, k3],
2 x 8 row-major), also lens_sensitivity (6C, 8L): d [dtheta, dt] / d lens.
Bad input raises ValueError naming the problem. Releases the GIL while solving.)doc");
}

void register_ba(py::module_& m) {
  def_bundle_adjust(m, "bundle_adjust", ba::AnalyticCosts());
  RegisterManifoldValues(m);

  m.def(
      "evaluate_free_cost",
      [](const Eigen::Matrix3d& K, const Eigen::VectorXd& observed, const Eigen::VectorXd& pose,
         const Eigen::VectorXd& point, const std::vector<bool>& want) {
        const ba::FreePointReprojectionCost cost(IntrinsicsOf(K), Vec2(observed, "observed"));
        return EvaluateCost(cost, {pose, point}, want);
      },
      py::arg("K"), py::arg("observed"), py::arg("pose"), py::arg("point"), py::arg("want") = std::vector<bool>{true, true},
      "Diagnostics: (ok, residual, [J_pose, J_point]) of the FREE reprojection cost.");
  m.def(
      "evaluate_plane_cost",
      [](const Eigen::Matrix3d& K, const Eigen::VectorXd& observed, const Eigen::VectorXd& pose,
         const Eigen::VectorXd& plane, const Eigen::VectorXd& ab, const std::vector<bool>& want) {
        const ba::PlanePointReprojectionCost cost(IntrinsicsOf(K), Vec2(observed, "observed"));
        return EvaluateCost(cost, {pose, plane, ab}, want);
      },
      py::arg("K"), py::arg("observed"), py::arg("pose"), py::arg("plane"), py::arg("ab"),
      py::arg("want") = std::vector<bool>{true, true, true},
      "Diagnostics: (ok, residual, [J_pose, J_plane, J_ab]) of the COPLANAR reprojection cost.");
  m.def(
      "evaluate_relief_cost",
      [](const Eigen::Matrix3d& K, const Eigen::VectorXd& observed, double spacing, const Eigen::VectorXd& pose,
         const Eigen::VectorXd& plane, const Eigen::VectorXd& ab, const Eigen::VectorXd& nodes,
         const std::vector<bool>& want) {
        const ba::ReliefGrid grid = OneCellGrid(spacing, nodes);
        const ba::ReliefReprojectionCost cost(
            new ba::PlanePointReprojectionCost(IntrinsicsOf(K), Vec2(observed, "observed")), grid, 0);
        std::vector<Eigen::VectorXd> blocks = {pose, plane, ab};
        AppendNodeBlocks(nodes, &blocks);
        return EvaluateCost(cost, blocks, want);
      },
      py::arg("K"), py::arg("observed"), py::arg("spacing"), py::arg("pose"), py::arg("plane"), py::arg("ab"),
      py::arg("nodes"), py::arg("want") = std::vector<bool>(),
      "Diagnostics: (ok, residual, [J_pose, J_plane, J_ab, J_node...]) of the COPLANAR cost on a relief of one\n"
      "cell [0, spacing]^2: 4 nodes, its corners' heights (order (0,0), (1,0), (0,1), (1,1)), bilinear; or 16,\n"
      "the cubic B-spline's control points at spacing * (i - 1, j - 1), node j * 4 + i. `want`: the\n"
      "Jacobians asked for (empty: all).");
  m.def(
      "evaluate_projector_cost",
      [](const Eigen::VectorXd& projector, double weight, const Eigen::VectorXd& surface_map,
         const Eigen::VectorXd& lens, const Eigen::VectorXd& ab, const std::vector<bool>& want) {
        const ba::ProjectorSurfaceCost cost(Vec2(projector, "projector"), weight);
        return EvaluateCost(cost, {surface_map, lens, ab}, want);
      },
      py::arg("projector"), py::arg("weight"), py::arg("surface_map"), py::arg("lens"), py::arg("ab"),
      py::arg("want") = std::vector<bool>{true, true, true},
      "Diagnostics: (ok, residual, [J_map, J_lens, J_ab]) of the projector surface cost (normalised pixel).");
  m.def(
      "evaluate_relief_projector_cost",
      [](const Eigen::VectorXd& projector, double weight, const Eigen::VectorXd& surface_map, const Eigen::VectorXd& lens,
         double spacing, const Eigen::VectorXd& ab, const Eigen::VectorXd& apex, const Eigen::VectorXd& nodes,
         const std::vector<bool>& want) {
        const ba::ReliefGrid grid = OneCellGrid(spacing, nodes);
        const ba::ReliefProjectorCost cost(new ba::ProjectorSurfaceCost(Vec2(projector, "projector"), weight), grid, 0);
        std::vector<Eigen::VectorXd> blocks = {surface_map, lens, ab, apex};
        AppendNodeBlocks(nodes, &blocks);
        return EvaluateCost(cost, blocks, want);
      },
      py::arg("projector"), py::arg("weight"), py::arg("surface_map"), py::arg("lens"), py::arg("spacing"),
      py::arg("ab"), py::arg("apex"), py::arg("nodes"), py::arg("want") = std::vector<bool>(),
      "Diagnostics: (ok, residual, [J_map, J_lens, J_ab, J_apex, J_node...]) of the projector cost of a centre on\n"
      "a relief of one cell [0, spacing]^2 (nodes as for evaluate_relief_cost), seen along the ray from the\n"
      "apex [1 / e, C_a / e, C_b / e]. `want`: the Jacobians asked for (empty: all).");
  m.def(
      "point_on_plane",
      [](const Eigen::Vector4d& plane, const Eigen::Vector2d& ab) { return ba::PointOnPlane(plane.data(), ab.data()); },
      py::arg("plane"), py::arg("ab"), "World point of plane coordinates (a, b) on the plane [n, d].");
  m.def(
      "plane_manifold",
      [](const Eigen::VectorXd& reference_normal, bool fix_offset, const Eigen::VectorXd& x, const Eigen::VectorXd& y,
         const Eigen::VectorXd& delta) {
        if (reference_normal.size() != 3) throw std::invalid_argument("reference_normal: expected 3 values");
        return ManifoldFunctions(ba::PlaneManifold(reference_normal, fix_offset), x, y, delta);
      },
      py::arg("reference_normal"), py::arg("fix_offset"), py::arg("x"), py::arg("y"), py::arg("delta"),
      "Diagnostics: Plus(x, delta), Minus(y, x) and their Jacobians at x of the plane manifold.");
  m.def(
      "fixed_distance_pose_manifold",
      [](const Eigen::VectorXd& reference_translation, const Eigen::VectorXd& x, const Eigen::VectorXd& y,
         const Eigen::VectorXd& delta) {
        if (reference_translation.size() != 3) throw std::invalid_argument("reference_translation: expected 3 values");
        return ManifoldFunctions(ba::FixedDistancePoseManifold(reference_translation), x, y, delta);
      },
      py::arg("reference_translation"), py::arg("x"), py::arg("y"), py::arg("delta"),
      "Diagnostics: Plus, Minus and Jacobians of the scale-gauge pose manifold.");
}

}  // namespace calibproj::bindings
