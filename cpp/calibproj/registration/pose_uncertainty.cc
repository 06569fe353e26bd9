#include "calibproj/registration/pose_uncertainty.h"

#include <algorithm>
#include <cmath>
#include <string>
#include <stdexcept>

namespace calibproj::registration {

int PoseUncertainty::num_lenses() const {
  return lens_block.empty() ? 0 : std::max(0, *std::max_element(lens_block.begin(), lens_block.end()) + 1);
}

std::vector<int> PoseUncertainty::ParametersOf(int k) const {
  std::vector<int> rows;
  for (int i = 0; i < 6; ++i) rows.push_back(6 * k + i);
  const int block = lens_block.empty() ? -1 : lens_block[k];
  const int first = 6 * static_cast<int>(cameras.size()) + kLensSize * block;
  for (int i = 0; i < kLensSize && block >= 0; ++i) rows.push_back(first + i);
  return rows;
}

void PoseUncertainty::Check() const {
  if (!lens_block.empty() && lens_block.size() != cameras.size()) {
    throw std::invalid_argument("lens blocks: " + std::to_string(lens_block.size()) + " for " +
                                std::to_string(cameras.size()) + " cameras");
  }
  std::vector<int> owners(cameras.size(), 0);
  for (int block : lens_block) {
    if (block < -1 || block >= static_cast<int>(cameras.size())) {
      throw std::invalid_argument("lens blocks: block " + std::to_string(block) + " out of range");
    }
    if (block >= 0 && ++owners[block] > 1) {
      throw std::invalid_argument("lens blocks: block " + std::to_string(block) + " given to two cameras");
    }
  }
  for (int block = 0; block < num_lenses(); ++block) {
    if (owners[block] == 0) throw std::invalid_argument("lens blocks: block " + std::to_string(block) + " is nobody's");
  }
  const auto size = static_cast<Eigen::Index>(6 * cameras.size() + kLensSize * num_lenses());
  if (covariance.rows() != size || covariance.cols() != size) {
    throw std::invalid_argument("pose covariance: " + std::to_string(covariance.rows()) + " x " +
                                std::to_string(covariance.cols()) + " for " + std::to_string(cameras.size()) +
                                " cameras and " + std::to_string(num_lenses()) +
                                " lenses (needs 6 rows and columns per camera, 8 per lens)");
  }
  if (!covariance.allFinite()) throw std::invalid_argument("pose covariance: non-finite value");
  if (noise_px.size() != cameras.size()) {
    throw std::invalid_argument("noise: " + std::to_string(noise_px.size()) + " values for " +
                                std::to_string(cameras.size()) + " cameras");
  }
  for (double noise : noise_px) {
    if (!(noise > 0.0 && std::isfinite(noise))) throw std::invalid_argument("noise: every camera needs a positive finite noise");
  }
  if (!cameras.empty() && IndexOf(reference) < 0) {
    throw std::invalid_argument("pose covariance: the reference camera '" + reference + "' is not one of its cameras");
  }
}

PoseUncertainty PoseUncertainty::Scaled(double factor) const {
  PoseUncertainty out = *this;
  Eigen::VectorXd scale = Eigen::VectorXd::Ones(covariance.rows());
  for (size_t c = 0; c < cameras.size(); ++c) scale.segment<3>(6 * static_cast<Eigen::Index>(c) + 3).setConstant(factor);
  out.covariance = scale.asDiagonal() * covariance * scale.asDiagonal();
  return out;
}

PoseUncertainty PoseUncertainty::Named(const std::vector<std::string>& names) const {
  PoseUncertainty out = *this;
  const auto rename = [&](std::string* camera) {
    const bool digits = !camera->empty() && camera->size() < 10 &&
                        camera->find_first_not_of("0123456789") == std::string::npos;
    if (!digits || std::stoul(*camera) >= names.size()) {
      throw std::invalid_argument("pose covariance: camera '" + *camera + "' is not an index of the " +
                                  std::to_string(names.size()) + " names");
    }
    *camera = names[std::stoul(*camera)];
  };
  for (auto& camera : out.cameras) rename(&camera);
  if (!out.cameras.empty()) rename(&out.reference);
  return out;
}

int PoseUncertainty::IndexOf(const std::string& camera) const {
  const auto it = std::find(cameras.begin(), cameras.end(), camera);
  return it == cameras.end() ? -1 : static_cast<int>(it - cameras.begin());
}

}  // namespace calibproj::registration
