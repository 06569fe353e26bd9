#include "calibproj/selfcal/refinement.h"

#include <opencv2/calib3d.hpp>
#include <opencv2/core/eigen.hpp>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <limits>
#include <set>
#include <stdexcept>

#include "calibproj/detect/lens.h"
#include "calibproj/formats/files.h"
#include "calibproj/selfcal/lens_problem.h"
#include "calibproj/selfcal/option_table.h"
#include "calibproj/selfcal/planar_autocalibration.h"
#include "calibproj/selfcal/self_calibration.h"

namespace calibproj::selfcal {

namespace {

using formats::FormatNumber;
using Log = std::function<void(const std::string&)>;

// Entries are freed in stages, each kept only if the data determine it: the most robust
// first; a free principal point, k3 and tangential terms make a partial view's problem
// ill-conditioned and are tried last.
const std::vector<std::vector<std::string>>& Stages() {
  static const std::vector<std::vector<std::string>> stages = {{"focal", "k1"}, {"k2"}, {"k3"}, {"tangential"}, {"pp"}};
  return stages;
}

// Entries a camera may free only when its observations reach far enough towards the
// image corners: fitted on a central patch they do not hold in the rest of the image.
bool NeedsCoverage(const std::string& entry) { return entry == "k3" || entry == "pp"; }

std::string Percent(double share, int decimals) {
  return FormatNumber(decimals == 0 ? "%.0f" : "%.2f", 100.0 * share) + "%";
}

// The 1-sigma uncertainty, in pixels, at which each group counts as determined.
double LimitOf(const std::string& group, const SelfCalibrationOptions& options, double focal, double noise_px) {
  if (group == kFocalGroup) return options.max_focal_sigma * focal;
  if (group == kPrincipalPointGroup) return std::max(options.max_principal_point_sigma_px, noise_px);
  return std::max(options.max_distortion_sigma_px, options.distortion_sigma_noise_ratio * noise_px);
}

// 1 sigma of each refined group, in the order focal, principal point, distortion:
// focal (px), principal point (px, worse axis) and the distortion's displacement (px,
// along its worse axis, RMS over `seen`, the normalised coordinates of the camera's
// observations: elsewhere in the image nothing measured it).
std::vector<std::pair<std::string, double>> GroupSigmas(const LensCovariance& covariance, const Lens& lens,
                                                        const LensShape& shape,
                                                        const std::vector<Eigen::Vector2d>& seen) {
  const Eigen::Matrix<double, kLensSize, 1> variances = covariance.diagonal();
  std::vector<std::pair<std::string, double>> out;
  if (variances(kFocal) > 0.0) out.emplace_back(kFocalGroup, std::sqrt(variances(kFocal)));
  if (variances(kCx) > 0.0 || variances(kCy) > 0.0) {
    out.emplace_back(kPrincipalPointGroup, std::sqrt(std::max(variances(kCx), variances(kCy))));
  }
  const int distortion[5] = {kK1, kK2, kP1, kP2, kK3};
  bool any = false;
  for (const int k : distortion) any = any || variances(k) > 0.0;
  if (any && !seen.empty()) {
    Eigen::Matrix<double, 5, 5> block;
    for (int a = 0; a < 5; ++a) {
      for (int b = 0; b < 5; ++b) block(a, b) = covariance(distortion[a], distortion[b]);
    }
    double sum = 0.0;
    for (const Eigen::Vector2d& p : seen) {
      const double x = p(0), y = p(1), r2 = x * x + y * y;
      // d(displacement)/d(k1, k2, p1, p2, k3), pixels.
      Eigen::Matrix<double, 2, 5> J;
      J << x * r2, x * r2 * r2, 2 * x * y, r2 + 2 * x * x, x * r2 * r2 * r2,  //
          y * r2, y * r2 * r2, r2 + 2 * y * y, 2 * x * y, y * r2 * r2 * r2;
      J *= lens(kFocal);
      J.row(1) *= shape.aspect;
      const Eigen::Matrix2d displacement = J * block * J.transpose();
      sum += Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d>(displacement, Eigen::EigenvaluesOnly).eigenvalues()(1);
    }
    out.emplace_back(kDistortionGroup, std::sqrt(std::max(sum / static_cast<double>(seen.size()), 0.0)));
  }
  return out;
}

std::string LensLine(const LensReport& report) {
  const Lens given = report.given.value_or(Lens::Zero()), result = report.result.value_or(Lens::Zero());
  const double change = report.given && report.result ? 100.0 * (result(kFocal) / given(kFocal) - 1.0) : 0.0;
  std::string refined;
  for (const auto& entry : report.refined) refined += (refined.empty() ? "" : ", ") + entry;
  std::string line = "camera " + report.camera + ": intrinsics refined (" + (refined.empty() ? "nothing" : refined) +
                     "): focal " + FormatNumber("%.2f", given(kFocal)) + " -> " + FormatNumber("%.2f", result(kFocal)) +
                     " px (" + FormatNumber("%+.2f", change) + " %, 1 sigma " +
                     (report.focal_sigma ? FormatNumber("%.3g", *report.focal_sigma) : "-") + " px), k1 " +
                     FormatNumber("%.4f", given(kK1)) + " -> " + FormatNumber("%.4f", result(kK1)) + ", noise " +
                     FormatNumber("%.3f", report.noise_px.value_or(0.0)) + " px";
  for (const auto& [group, why] : report.held) line += "; " + group + " held: " + why;
  if (report.misfit) line += "; " + *report.misfit;
  return line;
}

// The smooth pattern left in a camera's residuals, into its report; a misfit when it is
// both large and significant.
void JudgeSystematic(const std::optional<SystematicResidual>& measured, const SelfCalibrationOptions& options,
                     LensReport* report) {
  report->systematic_px = report->systematic_chi2 = std::nullopt;
  report->misfit.reset();
  if (!measured) return;
  const SystematicResidual& systematic = *measured;
  report->systematic_px = systematic.field_px;
  report->systematic_chi2 = systematic.chi2_drop;
  if (systematic.field_px > options.max_systematic_px && systematic.chi2_drop >= options.min_systematic_chi2) {
    report->misfit = "its residuals keep a smooth pattern of " + FormatNumber("%.2f", systematic.field_px) +
                     " px that its lens does not explain (chi-square " + FormatNumber("%.0f", systematic.chi2_drop) +
                     " for 12 parameters): an entry held at a wrong value, such as the principal point, or a lens "
                     "model that does not fit; its intrinsics are not to be trusted";
  }
}

// The reports by camera name, in insertion order.
class Reports {
 public:
  LensReport* Find(const std::string& name) {
    for (LensReport& report : all) {
      if (report.camera == name) return &report;
    }
    return nullptr;
  }
  LensReport& Set(LensReport report) {
    LensReport* found = Find(report.camera);
    if (found != nullptr) return *found = std::move(report);
    all.push_back(std::move(report));
    return all.back();
  }
  std::vector<LensReport> all;
};

struct Undetermined {
  std::string why, group;  // group empty: every group determined
  double excess = 0.0;
};

// The group of camera c's refined lens that the data determine worst, if beyond its
// limit, with why and by how much (sigma / limit); records the groups' uncertainties
// in `report`.
Undetermined UndeterminedGroup(const Problem& problem, int c, const Result& solution,
                               const SelfCalibrationOptions& options, LensReport& report) {
  const Lens lens = solution.lenses.row(c).transpose();
  const auto sigmas = GroupSigmas(solution.LensCovarianceOf(c, c), lens, problem.shapes[c],
                                  problem.Seen(c, options.max_sampled_points));
  Undetermined worst;
  for (const auto& [group, sigma] : sigmas) {
    if (group == kFocalGroup) report.focal_sigma = sigma;
    if (group == kPrincipalPointGroup) report.principal_point_sigma_px = sigma;
    if (group == kDistortionGroup) report.distortion_sigma_px = sigma;
    const double limit = LimitOf(group, options, lens(kFocal), solution.noise_px(c));
    if (sigma > limit && sigma / limit > worst.excess) {
      const std::string unit =
          group == kFocalGroup ? "px (" + Percent(sigma / lens(kFocal), 2) + ")" : std::string("px");
      worst = {"not determined by the data: " + group + " 1 sigma " + FormatNumber("%.3g", sigma) + " " + unit +
                   " exceeds " + FormatNumber("%.3g", limit) + " px",
               group, sigma / limit};
    }
  }
  return worst;
}

class Refinement {
 public:
  Refinement(Problem& problem, Reports& reports, const SelfCalibrationOptions& options, const Options& solve)
      : problem_(problem), reports_(reports), options_(options), solve_(solve) {}

  // Frees the requested entries stage by stage, keeping those that earn their place.
  Result ChooseAndRefine() {
    // A first robust solve with the first two stages' entries brings the residuals near
    // the noise, so that gross outliers can be told apart; the stages then start over.
    std::vector<std::string> first = Stages()[0];
    first.insert(first.end(), Stages()[1].begin(), Stages()[1].end());
    const std::vector<std::vector<int>> none(problem_.cameras.size());
    problem_.refine = problem_.StageEntries(first, none, {});
    problem_.Gate(problem_.Solve(ba::Loss::kCauchy, options_.first_loss_scale_px, solve_), options_);
    problem_.refine = none;
    problem_.lenses = problem_.start;
    Result solution = problem_.Solve(ba::Loss::kNone, 1.0, solve_);
    for (const auto& stage : Stages()) solution = RunStage(stage, std::move(solution));
    return solution;
  }

  // Refines the entries an earlier round chose, from where it left off.
  std::optional<Result> RefineAgain(const std::vector<LensReport>& earlier) {
    for (int c = static_cast<int>(problem_.cameras.size()) - 1; c >= 0; --c) {
      const std::string name = problem_.cameras[c];
      const auto before = std::find_if(earlier.begin(), earlier.end(), [&](const auto& r) { return r.camera == name; });
      LensReport* report = reports_.Find(name);
      if (report == nullptr || before == earlier.end()) continue;
      for (const auto& [entry, why] : before->held) report->Hold(entry, why);
      report->coverage = before->coverage;
      report->focal_sigma = before->focal_sigma;
      std::set<int> entries;
      for (const auto& entry : before->refined) {
        for (const int k : RefinableOf(entry).indices) entries.insert(k);
      }
      problem_.refine[c].assign(entries.begin(), entries.end());
      if (before->left_out) {
        report->left_out = true;
        problem_.DropCamera(c);
      }
    }
    if (!problem_.Solvable()) return std::nullopt;
    problem_.Gate(problem_.Solve(ba::Loss::kCauchy, options_.first_loss_scale_px, solve_), options_);
    return problem_.Solve(ba::Loss::kNone, 1.0, solve_);
  }

  // Holds at its given values the group whose uncertainty exceeds its limit the most
  // (over every camera), solves again, and repeats until every group left is
  // determined: one at a time, since holding one may determine the others (three
  // cameras do not determine three focal lengths; with one of them known they do). A
  // camera whose focal length is held is left out of the problem.
  std::optional<Result> HoldUndetermined(std::optional<Result> solution) {
    while (solution && problem_.Solvable()) {
      int worst_camera = -1;
      Undetermined worst;
      for (int c = 0; c < static_cast<int>(problem_.cameras.size()); ++c) {
        if (problem_.refine[c].empty()) continue;
        const Undetermined found =
            UndeterminedGroup(problem_, c, *solution, options_, *reports_.Find(problem_.cameras[c]));
        if (!found.group.empty() && (worst_camera < 0 || found.excess > worst.excess)) {
          worst_camera = c;
          worst = found;
        }
      }
      if (worst_camera < 0) return solution;
      const int c = worst_camera;
      LensReport& report = *reports_.Find(problem_.cameras[c]);
      std::set<int> held;
      for (const auto& entry : report.requested) {
        if (worst.group == kFocalGroup || worst.group == RefinableOf(entry).group) {
          report.HoldIfNot(entry, worst.why);
          for (const int k : RefinableOf(entry).indices) held.insert(k);
        }
      }
      auto& entries = problem_.refine[c];
      entries.erase(std::remove_if(entries.begin(), entries.end(), [&](int k) { return held.count(k) > 0; }),
                    entries.end());
      for (const int k : held) problem_.lenses(c, k) = problem_.given(c, k);
      if (worst.group == kFocalGroup) {  // nothing of this lens can be trusted: all of it is held, and left out
        report.left_out = true;
        problem_.DropCamera(c);
      }
      solution = problem_.Solvable() ? std::optional<Result>(problem_.Solve(ba::Loss::kNone, 1.0, solve_))
                                     : std::nullopt;
    }
    return solution;
  }

 private:
  // Frees the stage's requested entries and solves; a camera whose fit they do not
  // improve significantly gets them held at their given values and the stage starts
  // over from where it began. Returns the last solution.
  Result RunStage(const std::vector<std::string>& stage, Result solution) {
    const std::vector<std::vector<int>> before = problem_.refine;
    const ba::PoseMatrix poses = problem_.poses;
    const FloorMatrix points = problem_.points;
    const LensMatrix lenses = problem_.lenses;
    std::set<int> rejected;
    for (int c = 0; c < static_cast<int>(problem_.cameras.size()); ++c) {
      if (HoldForCoverage(c, stage)) rejected.insert(c);
    }
    while (true) {
      problem_.refine = problem_.StageEntries(stage, before, rejected);
      if (problem_.refine == before) return solution;  // nothing (left) to free: the state is the one it began with
      Result attempt = problem_.Solve(ba::Loss::kNone, 1.0, solve_);
      std::vector<std::pair<int, std::string>> failing;
      for (int c = 0; c < static_cast<int>(problem_.cameras.size()); ++c) {
        if (problem_.refine[c] == before[c]) continue;
        const int added = static_cast<int>(problem_.refine[c].size() - before[c].size());
        const std::string why = problem_.Insignificant(c, solution, attempt, added, options_);
        if (!why.empty()) failing.emplace_back(c, why);
      }
      if (failing.empty()) return attempt;
      for (const auto& [c, why] : failing) {
        rejected.insert(c);
        LensReport& report = *reports_.Find(problem_.cameras[c]);
        for (const auto& entry : stage) {
          if (Contains(report.requested, entry)) report.Hold(entry, why);
        }
      }
      problem_.poses = poses;
      problem_.points = points;
      problem_.lenses = lenses;
    }
  }

  // Whether camera c may not free the stage's entries because its observations do not
  // reach far enough towards the image corners (recorded in its report).
  bool HoldForCoverage(int c, const std::vector<std::string>& stage) {
    const double coverage = problem_.Coverage(c);
    LensReport* report = reports_.Find(problem_.cameras[c]);
    if (report != nullptr) report->coverage = coverage;
    std::vector<std::string> asked;
    for (const auto& entry : stage) {
      if (NeedsCoverage(entry) && Contains(problem_.requested[c], entry)) asked.push_back(entry);
    }
    if (asked.empty() || coverage >= options_.min_coverage) return false;
    for (const auto& entry : asked) {
      report->Hold(entry, "the floor reaches only " + Percent(coverage, 0) + " of the way to the image corners (at least " +
                              Percent(options_.min_coverage, 0) +
                              " needed): fitted there, it would not hold in the rest of the image");
    }
    return true;
  }

  Problem& problem_;
  Reports& reports_;
  const SelfCalibrationOptions& options_;
  const Options& solve_;
};

// Every camera's intrinsics after the refinement, the reports completed.
IntrinsicsMap RefinedIntrinsics(Problem& problem, const std::optional<Result>& solution,
                                const IntrinsicsMap& intrinsics, const IntrinsicsMap& given, Reports& reports,
                                const OrderedTexts& refused, const SelfCalibrationOptions& options, const Log& log) {
  if (!solution) {  // every other camera left out: nothing to refine these against
    for (size_t c = 0; c < problem.cameras.size(); ++c) {
      if (LensReport* report = reports.Find(problem.cameras[c])) {
        for (const auto& entry : report->requested) {
          report->HoldIfNot(entry,
                            "not determined: the other cameras' lenses are not either, and one camera alone does "
                            "not determine its own");
        }
      }
      problem.refine[c].clear();
    }
  }
  IntrinsicsMap refined;
  for (const auto& [name, value] : intrinsics) refined[name] = problem.Dropped(name) ? given.at(name) : value;
  for (size_t c = 0; c < problem.cameras.size(); ++c) {
    const std::string& name = problem.cameras[c];
    LensReport* report = reports.Find(name);
    if (report == nullptr || HasKey(refused, name)) continue;
    const Lens lens = solution && !problem.refine[c].empty() ? Lens(solution->lenses.row(c).transpose())
                                                             : Lens(problem.given.row(c).transpose());
    refined[name] = WithLens(given.at(name), lens);
    report->refined.clear();
    for (const auto& entry : report->requested) {
      if (!report->IsHeld(entry)) report->refined.push_back(entry);
    }
    report->result = lens;
    report->noise_px = solution ? std::optional<double>(solution->noise_px(c)) : std::nullopt;
    report->observations = problem.CountOf(static_cast<int>(c));
    JudgeSystematic(solution ? problem.Systematic(static_cast<int>(c), *solution) : std::nullopt, options, report);
    log(LensLine(*report));
  }
  for (const auto& [name, observations] : problem.dropped) {
    LensReport& report = *reports.Find(name);
    report.refined.clear();
    report.result = report.given;
    report.observations = observations;
    log(LensLine(report));
  }
  return refined;
}

}  // namespace

void SelfCalibrationOptions::Check() const {
  SelfCalibrationOptions copy = *this;
  VisitSelfCalibrationOptions(copy, [](const std::string& name, auto& value, const std::string&) {
    if (!(std::isfinite(static_cast<double>(value)) && value > 0)) {
      throw std::invalid_argument("self-calibration option " + name + " must be a positive number, got " +
                                  FormatNumber("%g", static_cast<double>(value)));
    }
  });
}

RefineRequest RefineRequest::Parse(const std::vector<std::string>& items) {
  RefineRequest request;
  for (const std::string& item : items) {
    const size_t equals = item.rfind('=');
    std::string camera = equals == std::string::npos ? "" : formats::Trimmed(item.substr(0, equals));
    if (camera.empty()) camera = kAllCameras;
    std::vector<std::string> chosen;
    const std::string names = equals == std::string::npos ? item : item.substr(equals + 1);
    size_t begin = 0;
    while (begin <= names.size()) {
      const size_t comma = std::min(names.find(',', begin), names.size());
      const std::string name = formats::Trimmed(names.substr(begin, comma - begin));
      if (!name.empty() && !Contains(chosen, name)) chosen.push_back(name);
      begin = comma + 1;
    }
    const std::string quoted = formats::PythonRepr(item);
    if (chosen.empty()) {
      throw std::invalid_argument("--refine-intrinsics " + quoted + ": no entry named (use e.g. focal,k1,k2)");
    }
    if (chosen == std::vector<std::string>{"none"}) {
      chosen.clear();
    } else if (Contains(chosen, "none")) {
      throw std::invalid_argument("--refine-intrinsics " + quoted +
                                  ": 'none' stands alone (CAMERA=none holds that camera's intrinsics)");
    }
    for (const std::string& name : chosen) {
      if (FindRefinable(name) == nullptr) {
        throw std::invalid_argument("--refine-intrinsics " + quoted + ": unknown entry " + formats::PythonRepr(name) +
                                    " (known: focal, pp, k1, k2, k3, tangential, none)");
      }
    }
    for (const auto& [named, unused] : request.entries) {
      if (named == camera) {
        throw std::invalid_argument("--refine-intrinsics: camera " + formats::PythonRepr(camera) + " given twice");
      }
    }
    request.entries.emplace_back(camera, chosen);
  }
  return request;
}

const std::vector<std::string>& RefineRequest::Of(const std::string& camera) const {
  static const std::vector<std::string> nothing;
  const std::vector<std::string>* all = &nothing;
  for (const auto& [named, chosen] : entries) {
    if (named == camera) return chosen;
    if (named == kAllCameras) all = &chosen;
  }
  return *all;
}

std::vector<std::string> RefineRequest::CamerasNamed() const {
  std::vector<std::string> out;
  for (const auto& [named, unused] : entries) {
    if (named != kAllCameras) out.push_back(named);
  }
  return out;
}

void RefineRequest::CheckCameras(const std::vector<std::string>& names) const {
  for (const std::string& named : CamerasNamed()) {
    if (!Contains(names, named)) {
      std::string list;
      for (const auto& name : names) list += (list.empty() ? "" : ", ") + name;
      throw std::invalid_argument("--refine-intrinsics: no camera named " + formats::PythonRepr(named) +
                                  " (cameras: " + (list.empty() ? "none" : list) + ")");
    }
  }
}

Lens LensBlockOf(const formats::CameraIntrinsics& in) {
  double dist[5] = {0.0, 0.0, 0.0, 0.0, 0.0};
  for (size_t k = 0; k < std::min<size_t>(5, in.dist.size()); ++k) dist[k] = in.dist[k];
  Lens lens;
  lens << in.K(0, 0), in.K(0, 2), in.K(1, 2), dist[0], dist[1], dist[2], dist[3], dist[4];
  return lens;
}

formats::CameraIntrinsics WithLens(const formats::CameraIntrinsics& given, const Lens& lens) {
  formats::CameraIntrinsics out = given;
  const double scale = lens(kFocal) / given.K(0, 0);
  out.K << lens(kFocal), given.K(0, 1) * scale, lens(kCx), 0.0, given.K(1, 1) * scale, lens(kCy), 0.0, 0.0, 1.0;
  out.dist = {lens(kK1), lens(kK2), lens(kP1), lens(kP2), lens(kK3)};
  return out;
}

void LensReport::Hold(const std::string& entry, const std::string& why) {
  for (auto& [held_entry, reason] : held) {
    if (held_entry == entry) {
      reason = why;
      return;
    }
  }
  held.emplace_back(entry, why);
}

void LensReport::HoldIfNot(const std::string& entry, const std::string& why) {
  if (!IsHeld(entry)) held.emplace_back(entry, why);
}

bool LensReport::IsHeld(const std::string& entry) const { return HasKey(held, entry); }

bool HasKey(const OrderedTexts& items, const std::string& key) {
  return std::any_of(items.begin(), items.end(), [&](const auto& item) { return item.first == key; });
}

std::optional<std::string> WeakReason(const LensReport& report) {
  for (const auto& [entry, why] : report.held) {
    if (entry == kFocalGroup) return "its focal length was not refined (" + why + ")";
  }
  return report.misfit;
}

OrderedTexts MarkUntrustedLensesWeak(const SelfCalibration& result, formats::Calibration& calibration) {
  OrderedTexts marked;
  for (const LensReport& report : result.reports) {
    const std::optional<std::string> reason = WeakReason(report);
    if (!reason || calibration.PoseOf(report.camera) == nullptr) continue;
    for (auto& [name, metrics] : calibration.metrics) {
      if (name != report.camera || metrics.weak) continue;
      metrics.weak = true;
      marked.emplace_back(name, *reason);
    }
  }
  return marked;
}

nlohmann::ordered_json LensReport::ToJson() const {
  const auto optional = [](const std::optional<double>& value) {
    return value ? nlohmann::ordered_json(*value) : nlohmann::ordered_json(nullptr);
  };
  const auto text = [](const std::optional<std::string>& value) {
    return value ? nlohmann::ordered_json(*value) : nlohmann::ordered_json(nullptr);
  };
  const auto lens = [](const std::optional<Lens>& value) {
    nlohmann::ordered_json out = nlohmann::ordered_json::object();
    if (value) {
      for (int k = 0; k < kLensSize; ++k) out[kLensEntries[k]] = (*value)(k);
    }
    return out;
  };
  nlohmann::ordered_json held_json = nlohmann::ordered_json::object();
  for (const auto& [entry, why] : held) held_json[entry] = why;
  return {{"camera", camera},
          {"requested", requested},
          {"refined", refined},
          {"held", held_json},
          {"focal_sigma", optional(focal_sigma)},
          {"principal_point_sigma_px", optional(principal_point_sigma_px)},
          {"distortion_sigma_px", optional(distortion_sigma_px)},
          {"noise_px", optional(noise_px)},
          {"coverage", optional(coverage)},
          {"left_out", left_out},
          {"systematic_px", optional(systematic_px)},
          {"systematic_chi2", optional(systematic_chi2)},
          {"misfit", text(misfit)},
          {"weak_reason", text(WeakReason(*this))},
          {"observations", observations},
          {"given", lens(given)},
          {"result", lens(result)}};
}

Eigen::MatrixXd JointLensCovariance::Among(const std::vector<std::string>& names) const {
  std::vector<int> blocks;
  for (const std::string& name : names) {
    const auto found = std::find(cameras.begin(), cameras.end(), name);
    if (found == cameras.end()) throw std::invalid_argument("no refined lens of camera '" + name + "'");
    blocks.push_back(static_cast<int>(found - cameras.begin()));
  }
  const int n = static_cast<int>(blocks.size());
  Eigen::MatrixXd out(kLensSize * n, kLensSize * n);
  for (int a = 0; a < n; ++a) {
    for (int b = 0; b < n; ++b) {
      out.block<kLensSize, kLensSize>(kLensSize * a, kLensSize * b) =
          matrix.block<kLensSize, kLensSize>(kLensSize * blocks[a], kLensSize * blocks[b]);
    }
  }
  return out;
}

const LensReport* SelfCalibration::ReportOf(const std::string& camera) const {
  for (const LensReport& report : reports) {
    if (report.camera == camera) return &report;
  }
  return nullptr;
}

OrderedTexts RefusedCameras(const RefineRequest& request, const IntrinsicsMap& intrinsics,
                            const std::vector<std::string>& camera_names) {
  request.CheckCameras(camera_names);
  OrderedTexts refused;
  for (const std::string& name : camera_names) {
    const auto found = intrinsics.find(name);
    if (request.Of(name).empty() || found == intrinsics.end()) continue;
    const std::vector<double>& dist = found->second.dist;
    if (dist.size() > 5 && std::any_of(dist.begin() + 5, dist.end(), [](double c) { return c != 0.0; })) {
      refused.emplace_back(name, "its distortion uses " + std::to_string(dist.size()) +
                                     " coefficients; self-calibration refines OpenCV's 5-coefficient model (k1, k2, "
                                     "p1, p2, k3)");
    }
  }
  return refused;
}

SelfCalibration SelfCalibrate(const formats::Tracks& tracks, const IntrinsicsMap& intrinsics,
                              const formats::Calibration& calibration, const RefineRequest& request,
                              const SelfCalibrationOptions& options, int num_threads, const IntrinsicsMap* given_or_null,
                              const std::vector<LensReport>* earlier, const Log& log) {
  options.Check();
  tracks.Check();
  calibration.Check();
  const IntrinsicsMap& given = given_or_null != nullptr ? *given_or_null : intrinsics;
  const OrderedTexts refused = RefusedCameras(request, given, tracks.cameras);
  for (const std::string& name : tracks.cameras) {
    if (calibration.PoseOf(name) != nullptr && intrinsics.count(name) && !given.count(name)) {
      throw std::invalid_argument("self-calibration: camera " + name + " has intrinsics but no given ones");
    }
  }
  Problem problem(tracks, intrinsics, calibration, request, refused, given);
  Reports reports;
  for (size_t c = 0; c < problem.cameras.size(); ++c) {
    const std::string& name = problem.cameras[c];
    if (request.Of(name).empty()) continue;
    LensReport report;
    report.camera = name;
    report.requested = request.Of(name);
    report.given = problem.given.row(c).transpose();
    reports.Set(report);
  }
  for (const auto& [name, reason] : refused) {
    LensReport report;
    report.camera = name;
    report.requested = request.Of(name);
    for (const auto& entry : report.requested) report.Hold(entry, reason);
    reports.Set(report);
  }
  SelfCalibration out;
  if (problem.Empty()) {
    out.intrinsics = intrinsics;
    out.reports = reports.all;
    return out;
  }
  Options solve;
  solve.max_iterations = options.lens_solver_iterations;
  solve.num_threads = num_threads;
  Refinement refinement(problem, reports, options, solve);
  std::optional<Result> solution =
      earlier != nullptr ? refinement.RefineAgain(*earlier) : std::optional<Result>(refinement.ChooseAndRefine());
  solution = refinement.HoldUndetermined(std::move(solution));
  if (solution && problem.HoldAtGiven()) {  // a later round held an entry the first one had moved
    solution = problem.Solve(ba::Loss::kNone, 1.0, solve);
  }
  out.intrinsics = RefinedIntrinsics(problem, solution, intrinsics, given, reports, refused, options, log);
  out.reports = reports.all;
  if (solution) {  // the joint covariance of every lens the solution refined
    std::vector<int> chosen;
    for (size_t c = 0; c < problem.cameras.size(); ++c) {
      const std::string& name = problem.cameras[c];
      if (!problem.refine[c].empty() && reports.Find(name) != nullptr && !HasKey(refused, name)) {
        chosen.push_back(static_cast<int>(c));
        out.lens_covariance.cameras.push_back(name);
      }
    }
    const int n = static_cast<int>(chosen.size());
    out.lens_covariance.matrix.resize(kLensSize * n, kLensSize * n);
    for (int a = 0; a < n; ++a) {
      for (int b = 0; b < n; ++b) {
        out.lens_covariance.matrix.block<kLensSize, kLensSize>(kLensSize * a, kLensSize * b) =
            solution->LensCovarianceOf(chosen[a], chosen[b]);
      }
    }
  }
  return out;
}

IntrinsicsMap ClosedFormStart(const formats::Tracks& tracks, const IntrinsicsMap& intrinsics,
                              const formats::Calibration& calibration, const RefineRequest& request,
                              const SelfCalibrationOptions& options, const Log& log) {
  options.Check();
  tracks.Check();
  calibration.Check();
  std::map<std::int64_t, int> lookup;
  for (size_t row = 0; row < calibration.point_ids.size(); ++row) lookup.emplace(calibration.point_ids[row], row);
  std::vector<std::pair<std::string, Eigen::Matrix3d>> homographies;
  std::map<std::string, double> known;
  for (const formats::CameraPose& pose : calibration.poses) {
    const auto in = intrinsics.find(pose.name);
    const auto position = std::find(tracks.cameras.begin(), tracks.cameras.end(), pose.name);
    if (in == intrinsics.end() || position == tracks.cameras.end()) continue;
    const int camera = static_cast<int>(position - tracks.cameras.begin());
    std::vector<cv::Point2d> floor, centred;
    for (int i = 0; i < tracks.camera_index.size(); ++i) {
      if (tracks.camera_index(i) != camera) continue;
      const auto row = lookup.find(tracks.point_ids[tracks.point_index(i)]);
      if (row == lookup.end()) continue;
      floor.emplace_back(calibration.points(row->second, 0), calibration.points(row->second, 1));
      centred.emplace_back(tracks.xy(i, 0) - in->second.K(0, 2), tracks.xy(i, 1) - in->second.K(1, 2));
    }
    if (static_cast<int>(floor.size()) < kPlanarMinPoints) continue;
    const cv::Mat H = cv::findHomography(floor, centred, cv::RANSAC, 3.0);
    if (H.empty()) continue;
    Eigen::Matrix3d homography;
    cv::cv2eigen(H, homography);
    homographies.emplace_back(pose.name, homography);
    if (!Contains(request.Of(pose.name), "focal")) {
      known[pose.name] = std::sqrt(in->second.K(0, 0) * in->second.K(1, 1));
    }
  }
  PlanarAutocalibration found;
  try {
    found = FocalLengths(homographies, known);
  } catch (const std::invalid_argument& error) {
    log(std::string("closed-form focal lengths not available (") + error.what() + "); starting from the given ones");
    return intrinsics;
  }
  IntrinsicsMap start = intrinsics;
  for (const auto& [name, focal] : found.focal) {
    const formats::CameraIntrinsics& in = intrinsics.at(name);
    if (std::abs(focal / in.K(0, 0) - 1.0) > options.closed_form_min_change) {
      log("camera " + name + ": starting from the closed-form focal length " + FormatNumber("%.1f", focal) +
          " px (given " + FormatNumber("%.1f", in.K(0, 0)) + " px)");
      Lens lens = LensBlockOf(in);
      lens(kFocal) = focal;
      start[name] = WithLens(in, lens);
    }
  }
  return start;
}

formats::Tracks ConvertTracks(const formats::Tracks& tracks, const IntrinsicsMap& given, const IntrinsicsMap& refined) {
  tracks.Check();
  formats::Tracks out = tracks;
  for (size_t c = 0; c < tracks.cameras.size(); ++c) {
    const auto from = given.find(tracks.cameras[c]), to = refined.find(tracks.cameras[c]);
    if (from == given.end() || to == refined.end()) continue;
    if (from->second.K == to->second.K && from->second.dist == to->second.dist) continue;
    const std::vector<int> rows = RowsOfCamera(tracks.camera_index, static_cast<int>(c));
    const auto raw = detect::DistortPixels(from->second, PointsOf(tracks.xy, rows));
    const auto undistorted = detect::UndistortPixels(to->second, raw);
    for (size_t k = 0; k < rows.size(); ++k) out.xy.row(rows[k]) << undistorted[k].x, undistorted[k].y;
  }
  return out;
}

std::string SelfCalibrationJson(const SelfCalibration& result, const IntrinsicsMap& given,
                                const SelfCalibrationOptions& options) {
  nlohmann::ordered_json options_json = nlohmann::ordered_json::object();
  SelfCalibrationOptions copy = options;
  VisitSelfCalibrationOptions(copy, [&](const std::string& name, auto& value, const std::string&) {
    options_json[name] = value;
  });
  nlohmann::ordered_json cameras = nlohmann::ordered_json::object();
  for (const LensReport& report : result.reports) {
    nlohmann::ordered_json entry = report.ToJson();
    const auto in = given.find(report.camera);
    if (in != given.end() && in->second.has_resolution) entry["given_intrinsics"] = formats::IntrinsicsBody(in->second);
    cameras[report.camera] = entry;
  }
  return formats::DumpSchemaJson("self_calibration", 1, {{"options", options_json}, {"cameras", cameras}});
}

}  // namespace calibproj::selfcal
