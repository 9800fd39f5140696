#include "core/stack.h"

#include <algorithm>
#include <cmath>

namespace u3mscan {

Eigen::Vector3d LightModel::DirectionFrom(const Eigen::Vector3d& point_in_world_mm) const {
  if (type == LightType::kDirectional) return direction_in_world;
  const Eigen::Vector3d to_light = position_in_world_mm - point_in_world_mm;
  const double d = to_light.norm();
  return d > 0.0 ? Eigen::Vector3d(to_light / d) : direction_in_world;
}

double LightModel::RelativeIrradianceAt(const Eigen::Vector3d& point_in_world_mm) const {
  if (type == LightType::kDirectional) return 1.0;
  const Eigen::Vector3d from_light = point_in_world_mm - position_in_world_mm;
  const double d2 = from_light.squaredNorm();
  if (d2 <= 0.0) return 0.0;
  double profile = 1.0;
  if (has_profile) {
    const double c = std::max(0.0, profile_axis_in_world.dot(from_light) / std::sqrt(d2));
    profile = std::pow(c, profile_exponent);
  }
  return profile / d2;
}

}  // namespace u3mscan
