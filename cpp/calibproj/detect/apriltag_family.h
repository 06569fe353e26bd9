#pragma once
// Owning handles for libapriltag's C tag families.

#include <memory>
#include <string>
#include <vector>

struct apriltag_family;

namespace calibproj::detect {

// A libapriltag family freed with its own <family>_destroy() when the handle dies.
using AprilTagFamilyPtr = std::unique_ptr<apriltag_family, void (*)(apriltag_family*)>;

// Names of the families this build of libapriltag ships ("tag36h11", ...).
const std::vector<std::string>& AprilTagFamilyNames();

// Creates the named family. Throws std::invalid_argument for an unknown name.
AprilTagFamilyPtr CreateAprilTagFamily(const std::string& name);

}  // namespace calibproj::detect
