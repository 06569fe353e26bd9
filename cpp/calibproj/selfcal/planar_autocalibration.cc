#include "calibproj/selfcal/planar_autocalibration.h"

#include <Eigen/LU>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace calibproj::selfcal {

namespace {

constexpr int kGaussNewtonIterations = 30;

using Homographies = std::vector<std::pair<std::string, Eigen::Matrix3d>>;

Eigen::Matrix3d Normalised(const Eigen::Matrix3d& H, const std::string& name) {
  if (!H.allFinite()) throw std::invalid_argument("camera " + name + ": expected a finite 3x3 homography");
  const double scale = H.norm();
  if (scale == 0.0 || std::abs(H.determinant()) < 1e-12 * scale * scale * scale) {
    throw std::invalid_argument("camera " + name + ": degenerate floor homography");
  }
  return H / scale;
}

Eigen::Vector3cd CircularPoint(const Eigen::Vector4d& x) {
  return {1.0, {x(0), x(1)}, {x(2), x(3)}};
}

// (h1.I)^2 + (h2.I)^2 and (h3.I)^2.
std::pair<std::complex<double>, std::complex<double>> ConicTerms(const Eigen::Matrix3d& H, const Eigen::Vector3cd& I) {
  const Eigen::Vector3cd v = H.cast<std::complex<double>>() * I;
  return {v(0) * v(0) + v(1) * v(1), v(2) * v(2)};
}

// The real f^2 >= 0 minimising |p + f^2 q| (a negative one would let a real point, a
// degenerate "circular point", satisfy the equations).
double BestF2(std::complex<double> p, std::complex<double> q) {
  const double denominator = std::norm(q);
  return denominator > 0.0 ? std::max(-(p * std::conj(q)).real() / denominator, 0.0) : 0.0;
}

double F2Of(const std::string& name, std::complex<double> p, std::complex<double> q,
            const std::map<std::string, double>& known) {
  const auto found = known.find(name);
  return found != known.end() ? found->second * found->second : BestF2(p, q);
}

// Per camera the real and imaginary parts of its equation, each focal length
// eliminated (or known), normalised by the size of its terms.
Eigen::VectorXd Residuals(const Eigen::Vector4d& x, const Homographies& H, const std::map<std::string, double>& known) {
  const Eigen::Vector3cd I = CircularPoint(x);
  Eigen::VectorXd out(2 * H.size());
  for (size_t k = 0; k < H.size(); ++k) {
    const auto [p, q] = ConicTerms(H[k].second, I);
    const std::complex<double> value = (p + F2Of(H[k].first, p, q, known) * q) / std::max(std::abs(p), 1e-300);
    out(2 * k) = value.real();
    out(2 * k + 1) = value.imag();
  }
  return out;
}

// Central differences: four unknowns, the residuals a few dozen.
Eigen::MatrixXd Jacobian(const Eigen::Vector4d& x, const Homographies& H, const std::map<std::string, double>& known) {
  Eigen::MatrixXd J(2 * H.size(), 4);
  for (int k = 0; k < 4; ++k) {
    Eigen::Vector4d step = Eigen::Vector4d::Zero();
    step(k) = 1e-7 * std::max(1.0, std::abs(x(k)));
    J.col(k) = (Residuals(x + step, H, known) - Residuals(x - step, H, known)) / (2.0 * step(k));
  }
  return J;
}

}  // namespace

PlanarAutocalibration FocalLengths(const Homographies& homographies, const std::map<std::string, double>& known) {
  for (const auto& [name, focal] : known) {
    // Its square enters the equations: it must stay finite.
    if (!(std::isfinite(focal) && focal > 0.0 && focal < 1e100)) {
      throw std::invalid_argument("camera " + name + ": a known focal length must be a positive number below 1e100");
    }
  }
  Homographies H;
  int unknown = 0;
  for (const auto& [name, homography] : homographies) {
    H.emplace_back(name, Normalised(homography, name));
    unknown += known.count(name) ? 0 : 1;
  }
  const int cameras = static_cast<int>(H.size());
  if (2 * cameras < unknown + 4) {
    throw std::invalid_argument("planar autocalibration: " + std::to_string(cameras) + " camera(s) with " +
                                std::to_string(unknown) + " unknown focal length(s) give " +
                                std::to_string(2 * cameras) + " equations for " + std::to_string(unknown + 4) +
                                " unknowns");
  }
  Eigen::Vector4d x(0.0, 1.0, 0.0, 0.0);  // z2 = i, z3 = 0: a metric frame of the floor
  for (int iteration = 0; iteration < kGaussNewtonIterations; ++iteration) {
    const Eigen::VectorXd r = Residuals(x, H, known);
    const Eigen::MatrixXd J = Jacobian(x, H, known);
    if (!r.allFinite() || !J.allFinite()) {
      throw std::invalid_argument("planar autocalibration: the circular points' equations are not finite");
    }
    const Eigen::Vector4d step = J.jacobiSvd(Eigen::ComputeThinU | Eigen::ComputeThinV).solve(-r);
    x += step;
    if (step.norm() < 1e-12 * std::max(1.0, x.norm())) break;
  }
  PlanarAutocalibration out;
  out.circular_point = CircularPoint(x);
  for (const auto& [name, homography] : H) {
    const auto [p, q] = ConicTerms(homography, out.circular_point);
    const double f2 = F2Of(name, p, q, known);
    out.residual[name] = std::abs(p + f2 * q) / std::max(std::abs(p), 1e-300);
    if (!known.count(name) && f2 > 0.0) out.focal[name] = std::sqrt(f2);
  }
  return out;
}

}  // namespace calibproj::selfcal
