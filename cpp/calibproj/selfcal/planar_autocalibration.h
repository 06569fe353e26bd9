#pragma once
// Focal lengths of cameras that see one plane, in closed form (planar autocalibration).
//
// Every camera maps the floor to its image by a homography H (floor coordinates to
// pixels centred on the principal point). The floor's two circular points I and its
// conjugate lie, in every image, on that camera's image of the absolute conic
// omega = diag(1, 1, f^2) (square pixels, known principal point), so for each camera
//
//     (h1 . I)^2 + (h2 . I)^2 + f^2 (h3 . I)^2 = 0        (h_k: rows of H)
//
// a complex equation, two real ones. The circular points are shared: in any frame of
// the floor they are I = (1, z2, z3) up to scale, four real unknowns, (1, i, 0) in a
// metric frame. Given I, each camera's f^2 is the least-squares solution of its
// equation, in closed form; I itself is found by Gauss-Newton on the four unknowns,
// starting from the frame the floor was reconstructed in (metric but for the nominal
// focal lengths' error). Four cameras or more are needed (2 N equations, N + 4
// unknowns), or fewer when some focal lengths are known: then I follows from those.
//
// This gives the self-calibration a start that does not depend on the focal lengths
// the user guessed.

#include <Eigen/Core>
#include <complex>
#include <map>
#include <string>
#include <utility>
#include <vector>

namespace calibproj::selfcal {

constexpr int kPlanarMinPoints = 8;  // per camera, for its floor homography

struct PlanarAutocalibration {
  std::map<std::string, double> focal;     // px, per camera whose focal was unknown and is found
  std::map<std::string, double> residual;  // per camera, normalised (about 0 when consistent)
  Eigen::Vector3cd circular_point;         // first entry 1
};

// The focal length of every camera not in `known`, from its floor homography (floor
// frame -> pixels centred on its principal point), the cameras in the order given.
// std::invalid_argument when the cameras cannot determine them (fewer equations than
// unknowns) or a homography is degenerate.
PlanarAutocalibration FocalLengths(const std::vector<std::pair<std::string, Eigen::Matrix3d>>& homographies,
                                   const std::map<std::string, double>& known);

}  // namespace calibproj::selfcal
