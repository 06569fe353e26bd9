#include "calibproj/detect/apriltag_family.h"

#include <apriltag/apriltag.h>
#include <apriltag/tag16h5.h>
#include <apriltag/tag25h9.h>
#include <apriltag/tag36h10.h>
#include <apriltag/tag36h11.h>
#include <apriltag/tagCircle21h7.h>
#include <apriltag/tagCircle49h12.h>
#include <apriltag/tagCustom48h12.h>
#include <apriltag/tagStandard41h12.h>
#include <apriltag/tagStandard52h13.h>

#include <stdexcept>

namespace calibproj::detect {

namespace {

struct FamilyFactory {
  const char* name;
  apriltag_family_t* (*create)();
  void (*destroy)(apriltag_family_t*);
};

// Every family libapriltag 3.3 installs a header for.
constexpr FamilyFactory kFactories[] = {
    {"tag16h5", tag16h5_create, tag16h5_destroy},
    {"tag25h9", tag25h9_create, tag25h9_destroy},
    {"tag36h10", tag36h10_create, tag36h10_destroy},
    {"tag36h11", tag36h11_create, tag36h11_destroy},
    {"tagCircle21h7", tagCircle21h7_create, tagCircle21h7_destroy},
    {"tagCircle49h12", tagCircle49h12_create, tagCircle49h12_destroy},
    {"tagCustom48h12", tagCustom48h12_create, tagCustom48h12_destroy},
    {"tagStandard41h12", tagStandard41h12_create, tagStandard41h12_destroy},
    {"tagStandard52h13", tagStandard52h13_create, tagStandard52h13_destroy},
};

}  // namespace

const std::vector<std::string>& AprilTagFamilyNames() {
  static const std::vector<std::string> names = [] {
    std::vector<std::string> out;
    for (const auto& factory : kFactories) out.emplace_back(factory.name);
    return out;
  }();
  return names;
}

AprilTagFamilyPtr CreateAprilTagFamily(const std::string& name) {
  for (const auto& factory : kFactories) {
    if (name != factory.name) continue;
    apriltag_family_t* family = factory.create();
    if (family == nullptr) throw std::runtime_error("libapriltag could not create family " + name);
    return AprilTagFamilyPtr(family, factory.destroy);
  }
  throw std::invalid_argument("unknown AprilTag family '" + name + "'");
}

}  // namespace calibproj::detect
