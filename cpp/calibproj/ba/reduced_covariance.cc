#include "calibproj/ba/reduced_covariance.h"

#include <ceres/ceres.h>

#include <Eigen/Cholesky>
#include <cmath>
#include <stdexcept>
#include <unordered_map>
#include <vector>

namespace calibproj::ba {

namespace {

// Below this reciprocal condition number (of the reduced system scaled to a unit
// diagonal) some direction is not determined.
constexpr double kMinReciprocalCondition = 1e-14;
constexpr int kMaxEliminatedSize = 3;

using RowMajor = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
using ConstJacobian = Eigen::Map<const RowMajor>;

// Where each variable block goes: an eliminated block's index, or a kept block's first
// column in the reduced system.
struct Layout {
  std::unordered_map<const double*, int> eliminated;
  std::unordered_map<const double*, int> kept_column;
  int kept_columns = 0;  // the considered parameters' columns follow them
  int columns = 0;
};

Layout MakeLayout(const ceres::Problem& problem, const std::vector<double*>& eliminated,
                  const std::vector<double*>& kept, int considered_columns) {
  Layout layout;
  for (size_t b = 0; b < eliminated.size(); ++b) {
    if (problem.ParameterBlockTangentSize(eliminated[b]) > kMaxEliminatedSize) {
      throw std::logic_error("reduced covariance: eliminated blocks have at most 3 tangent entries");
    }
    layout.eliminated.emplace(eliminated[b], static_cast<int>(b));
  }
  for (double* block : kept) {
    layout.kept_column.emplace(block, layout.columns);
    layout.columns += problem.ParameterBlockTangentSize(block);
  }
  layout.kept_columns = layout.columns;
  layout.columns += considered_columns;
  return layout;
}

// The residual blocks grouped by the eliminated block they involve (at most one each);
// the last group holds those that involve none.
std::vector<std::vector<ceres::ResidualBlockId>> GroupResiduals(const ceres::Problem& problem, const Layout& layout,
                                                                size_t num_eliminated) {
  std::vector<std::vector<ceres::ResidualBlockId>> groups(num_eliminated + 1);
  std::vector<ceres::ResidualBlockId> residuals;
  problem.GetResidualBlocks(&residuals);
  std::vector<double*> blocks;
  for (ceres::ResidualBlockId id : residuals) {
    problem.GetParameterBlocksForResidualBlock(id, &blocks);
    int group = static_cast<int>(num_eliminated);
    for (double* block : blocks) {
      const auto it = layout.eliminated.find(block);
      if (it == layout.eliminated.end()) continue;
      if (group != static_cast<int>(num_eliminated)) throw std::logic_error("reduced covariance: a residual joins two points");
      group = it->second;
    }
    groups[group].push_back(id);
  }
  return groups;
}

// A Jacobian of the residual r before the robust loss made what Ceres evaluates with it:
// sqrt(rho') (J - alpha / |r|^2 r r^T J) (ceres/internal/corrector.cc).
void ApplyLoss(const ceres::LossFunction* loss, const Eigen::VectorXd& r, RowMajor* J) {
  if (loss == nullptr) return;
  const double squared_norm = r.squaredNorm();
  double rho[3];
  loss->Evaluate(squared_norm, rho);
  const double sqrt_rho1 = std::sqrt(rho[1]);
  if (squared_norm == 0.0 || rho[2] <= 0.0) {
    *J *= sqrt_rho1;
    return;
  }
  const double alpha = 1.0 - std::sqrt(1.0 + 2.0 * squared_norm * rho[2] / rho[1]);
  *J = sqrt_rho1 * (*J - (alpha / squared_norm) * r * (r.transpose() * *J));
}

// One kept block's part of a residual block's Jacobian.
struct KeptPart {
  int column = 0;
  int size = 0;
  const double* jacobian = nullptr;  // rows x size, row-major
  int offset = 0;                     // in the group's compact columns
};

// Accumulates one eliminated block's group (or the group of residuals without one):
// S += F^T F, and S -= W^T (E^T E)^-1 W with W = E^T F, on the kept blocks the group
// touches.
class GroupReducer {
 public:
  GroupReducer(ceres::Problem* problem, const Layout& layout, const ConsideredParameters* considered,
               Eigen::MatrixXd* S)
      : problem_(problem),
        layout_(layout),
        considered_(considered),
        S_(S),
        W_(Eigen::MatrixXd::Zero(kMaxEliminatedSize, layout.columns)),
        compact_(Eigen::MatrixXd::Zero(kMaxEliminatedSize, layout.columns)),
        update_(static_cast<size_t>(layout.columns) * layout.columns),
        touched_column_(layout.columns, false) {}

  void Reduce(const std::vector<ceres::ResidualBlockId>& group, const double* eliminated) {
    EtE_.setZero();
    touched_.clear();
    for (ceres::ResidualBlockId id : group) AddResidual(id, eliminated);
    if (eliminated != nullptr && !touched_.empty()) Eliminate(problem_->ParameterBlockTangentSize(eliminated));
    for (const KeptPart& part : touched_) {
      W_.middleCols(part.column, part.size).setZero();
      touched_column_[part.column] = false;
    }
  }

 private:
  void Eliminate(int size) {
    // Gather the touched columns side by side: one product makes the whole update.
    int width = 0;
    for (KeptPart& part : touched_) {
      compact_.block(0, width, size, part.size) = W_.block(0, part.column, size, part.size);
      part.offset = width;
      width += part.size;
    }
    const auto W = compact_.block(0, 0, size, width);
    Eigen::Map<Eigen::MatrixXd> update(update_.data(), width, width);
    if (size == 3) {
      update.noalias() = W.transpose() * (InverseOf<3>() * W);
    } else if (size == 2) {
      update.noalias() = W.transpose() * (InverseOf<2>() * W.topRows(2));
    } else {
      update.noalias() = W.transpose() * (InverseOf<1>() * W.topRows(1));
    }
    for (const KeptPart& a : touched_) {
      for (const KeptPart& b : touched_) {
        S_->block(a.column, b.column, a.size, b.size) -= update.block(a.offset, b.offset, a.size, b.size);
      }
    }
  }

  // (E^T E)^-1 of a point block of N tangent entries.
  template <int N>
  Eigen::Matrix<double, N, N> InverseOf() const {
    const Eigen::Matrix<double, N, N> EtE = EtE_.topLeftCorner<N, N>();
    Eigen::Matrix<double, N, N> inverse;
    bool invertible = false;
    double determinant = 0.0;
    EtE.computeInverseAndDetWithCheck(inverse, determinant, invertible, 0.0);
    if (!invertible || !(determinant > 0.0) || !(EtE.diagonal().array() > 0.0).all()) {
      throw std::runtime_error("covariance: a point is not determined by its observations");
    }
    return inverse;
  }

  void AddResidual(ceres::ResidualBlockId id, const double* eliminated) {
    problem_->GetParameterBlocksForResidualBlock(id, &blocks_);
    const int rows = problem_->GetCostFunctionForResidualBlock(id)->num_residuals();
    residuals_.resize(rows);
    storage_.resize(blocks_.size());
    pointers_.assign(blocks_.size(), nullptr);
    parts_.clear();
    int eliminated_slot = -1;
    for (size_t k = 0; k < blocks_.size(); ++k) {
      const auto kept = layout_.kept_column.find(blocks_[k]);
      const bool is_eliminated = blocks_[k] == eliminated;
      if (kept == layout_.kept_column.end() && !is_eliminated) continue;
      const int size = problem_->ParameterBlockTangentSize(blocks_[k]);
      storage_[k].resize(static_cast<size_t>(rows) * size);
      pointers_[k] = storage_[k].data();
      if (is_eliminated) {
        eliminated_slot = static_cast<int>(k);
      } else {
        parts_.push_back({kept->second, size, storage_[k].data()});
      }
    }
    if (!problem_->EvaluateResidualBlockAssumingParametersUnchanged(id, /*apply_loss_function=*/true, nullptr,
                                                                    residuals_.data(), pointers_.data())) {
      throw std::runtime_error("covariance: a residual could not be evaluated at the solution");
    }
    AddConsidered(id, rows);
    for (const KeptPart& a : parts_) {
      const ConstJacobian Ja(a.jacobian, rows, a.size);
      for (const KeptPart& b : parts_) {
        S_->block(a.column, b.column, a.size, b.size).noalias() += Ja.transpose().lazyProduct(ConstJacobian(b.jacobian, rows, b.size));
      }
    }
    if (eliminated_slot < 0) return;
    const int size = problem_->ParameterBlockTangentSize(eliminated);
    const ConstJacobian E(storage_[eliminated_slot].data(), rows, size);
    EtE_.topLeftCorner(size, size).noalias() += E.transpose().lazyProduct(E);
    for (const KeptPart& a : parts_) {
      W_.block(0, a.column, size, a.size).noalias() += E.transpose().lazyProduct(ConstJacobian(a.jacobian, rows, a.size));
      if (!touched_column_[a.column]) {
        touched_column_[a.column] = true;
        touched_.push_back({a.column, a.size, nullptr, 0});
      }
    }
  }

  // The considered parameters' part of the residual block's Jacobian, as a kept part.
  void AddConsidered(ceres::ResidualBlockId id, int rows) {
    if (considered_ == nullptr) return;
    const int first = considered_->jacobian(id, &raw_);
    if (raw_.cols() == 0) return;
    if (raw_.rows() != rows || first < 0 || first + raw_.cols() > considered_->columns) {
      throw std::logic_error("reduced covariance: a considered Jacobian outside its columns");
    }
    considered_jacobian_ = raw_;
    const ceres::LossFunction* loss = problem_->GetLossFunctionForResidualBlock(id);
    if (loss != nullptr) {
      Eigen::VectorXd r(rows);
      if (!problem_->EvaluateResidualBlockAssumingParametersUnchanged(id, /*apply_loss_function=*/false, nullptr,
                                                                      r.data(), nullptr)) {
        throw std::runtime_error("covariance: a residual could not be evaluated at the solution");
      }
      ApplyLoss(loss, r, &considered_jacobian_);
    }
    parts_.push_back({layout_.kept_columns + first, static_cast<int>(raw_.cols()), considered_jacobian_.data()});
  }

  ceres::Problem* problem_;
  const Layout& layout_;
  const ConsideredParameters* considered_;
  Eigen::MatrixXd raw_;
  RowMajor considered_jacobian_;
  Eigen::MatrixXd* S_;
  Eigen::Matrix3d EtE_;
  Eigen::MatrixXd W_;  // E^T F of the group, on its touched columns (zero elsewhere)
  Eigen::MatrixXd compact_;     // W's touched columns side by side
  std::vector<double> update_;  // W^T (E^T E)^-1 W on them
  std::vector<bool> touched_column_;
  std::vector<KeptPart> touched_;  // kept blocks the group's residuals involve
  std::vector<double*> blocks_;
  std::vector<double> residuals_;
  std::vector<std::vector<double>> storage_;
  std::vector<double*> pointers_;
  std::vector<KeptPart> parts_;
};

// S^-1, scaled to a unit diagonal first (the blocks mix radians, lengths and pixels).
Eigen::MatrixXd Inverse(const Eigen::MatrixXd& S) {
  const Eigen::ArrayXd diagonal = S.diagonal().array();
  if (!(diagonal > 0.0).all()) throw std::runtime_error("covariance: a parameter no residual depends on");
  const Eigen::VectorXd scale = diagonal.rsqrt().matrix();
  const Eigen::MatrixXd scaled = scale.asDiagonal() * S * scale.asDiagonal();
  const Eigen::LLT<Eigen::MatrixXd> llt(scaled);
  if (llt.info() != Eigen::Success || llt.rcond() < kMinReciprocalCondition) {
    throw std::runtime_error("covariance: the Jacobian is rank deficient; the poses are not determined");
  }
  const Eigen::MatrixXd inverse = llt.solve(Eigen::MatrixXd::Identity(S.rows(), S.cols()));
  return scale.asDiagonal() * inverse * scale.asDiagonal();
}

// The reduced system over the kept blocks' and the considered parameters' columns.
Eigen::MatrixXd ReducedSystem(ceres::Problem* problem, const std::vector<double*>& eliminated, const Layout& layout,
                              const ConsideredParameters* considered) {
  const auto groups = GroupResiduals(*problem, layout, eliminated.size());
  Eigen::MatrixXd S = Eigen::MatrixXd::Zero(layout.columns, layout.columns);
  GroupReducer reducer(problem, layout, considered, &S);
  for (size_t b = 0; b < eliminated.size(); ++b) reducer.Reduce(groups[b], eliminated[b]);
  reducer.Reduce(groups.back(), nullptr);
  return S;
}

}  // namespace

Eigen::MatrixXd ReducedCovariance(ceres::Problem* problem, const std::vector<double*>& eliminated,
                                  const std::vector<double*>& kept) {
  const Layout layout = MakeLayout(*problem, eliminated, kept, 0);
  return Inverse(ReducedSystem(problem, eliminated, layout, nullptr));
}

ReducedSolution ReducedCovarianceWithSensitivity(ceres::Problem* problem, const std::vector<double*>& eliminated,
                                                 const std::vector<double*>& kept,
                                                 const ConsideredParameters& considered) {
  const Layout layout = MakeLayout(*problem, eliminated, kept, considered.columns);
  const Eigen::MatrixXd S = ReducedSystem(problem, eliminated, layout, &considered);
  const int n = layout.kept_columns;
  ReducedSolution out;
  out.covariance = Inverse(S.topLeftCorner(n, n));
  out.sensitivity = -out.covariance * S.topRightCorner(n, considered.columns);
  return out;
}

}  // namespace calibproj::ba
