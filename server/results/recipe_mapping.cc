// Recipe documents: validation and mapping to core/metrology/measurement.h specs.
#include "server/results/recipe_mapping.h"

#include <cmath>
#include <set>

namespace inspection {
namespace {

Status Invalid(const std::string& field, const std::string& what) {
  return Status::InvalidArgument(field + " " + what);
}

StatusOr<RegionOfInterest> MapRegion(const v1::RecipeRegion& r, const std::string& field) {
  RegionOfInterest roi;
  if (r.unit().empty() || r.unit() == "px") {
    roi.unit = RoiUnit::kPixel;
  } else if (r.unit() == "um") {
    roi.unit = RoiUnit::kMicrometre;
  } else {
    return Invalid(field + ".unit", "'" + r.unit() + "' is not a unit (px or um)");
  }
  const bool has_rect = r.x() != 0 || r.y() != 0 || r.width() != 0 || r.height() != 0;
  switch (r.shape()) {
    case v1::RecipeRegion::SHAPE_UNSPECIFIED:
    case v1::RecipeRegion::SHAPE_WHOLE_FIELD:
      if (has_rect || r.polygon_size() > 0) {
        return Invalid(field, "is the whole field: x, y, width, height and polygon must be unset");
      }
      roi.shape = RoiShape::kWholeField;
      return roi;
    case v1::RecipeRegion::SHAPE_RECTANGLE:
      if (r.polygon_size() > 0) return Invalid(field + ".polygon", "is not used by a rectangle");
      roi.shape = RoiShape::kRectangle;
      roi.x = r.x();
      roi.y = r.y();
      roi.width = r.width();
      roi.height = r.height();
      return roi;
    case v1::RecipeRegion::SHAPE_POLYGON:
      if (has_rect) return Invalid(field, "is a polygon: x, y, width and height must be unset");
      if (r.polygon_size() < 3) {
        return Invalid(field + ".polygon", "has " + std::to_string(r.polygon_size()) + " vertices; a polygon needs 3");
      }
      roi.shape = RoiShape::kPolygon;
      for (const auto& p : r.polygon()) roi.polygon.push_back({p.x(), p.y()});
      return roi;
    default:
      return Invalid(field + ".shape", "is not a known shape");
  }
}

// The option fields a measurement kind reads; any other set option is refused so a typo in
// intent (an L-filter on a step height) does not pass silently.
Status CheckUnusedOptions(const v1::RecipeMeasurement& m, MeasurementKind kind, const std::string& field) {
  const bool height = kind == MeasurementKind::kSa || kind == MeasurementKind::kSq || kind == MeasurementKind::kSp ||
                      kind == MeasurementKind::kSv || kind == MeasurementKind::kSz || kind == MeasurementKind::kSsk ||
                      kind == MeasurementKind::kSku;
  const bool volume = kind == MeasurementKind::kVolumeAbove || kind == MeasurementKind::kVolumeBelow;
  const std::string name = MeasurementKindName(kind);
  if (!height && kind != MeasurementKind::kRadius && (!m.form().empty() || m.form_order() != 0)) {
    return Invalid(field + ".form", "is not used by " + name);
  }
  if (!height && (m.s_filter_um() != 0 || m.l_filter_um() != 0)) {
    return Invalid(field + (m.s_filter_um() != 0 ? ".s_filter_um" : ".l_filter_um"), "is not used by " + name);
  }
  if (kind != MeasurementKind::kStepHeight && !m.step_fit().empty()) {
    return Invalid(field + ".step_fit", "is not used by " + name);
  }
  if (!volume && (!m.volume_reference().empty() || m.volume_reference_height_um() != 0 || !m.volume_unit().empty())) {
    return Invalid(field + ".volume_reference", "(and volume_*) is not used by " + name);
  }
  return Status::Ok();
}

StatusOr<MeasurementSpec> MapMeasurement(const v1::RecipeMeasurement& m, const std::string& field) {
  auto kind = ParseMeasurementKind(m.parameter());
  if (!kind.ok()) return Status::InvalidArgument(field + ".parameter: " + kind.status().message());
  INSPECT_RETURN_IF_ERROR(CheckUnusedOptions(m, *kind, field));
  MeasurementSpec spec;
  spec.kind = *kind;
  INSPECT_ASSIGN_OR_RETURN(spec.roi, MapRegion(m.roi(), field + ".roi"));
  if (m.has_reference_roi()) {
    INSPECT_ASSIGN_OR_RETURN(RegionOfInterest ref, MapRegion(m.reference_roi(), field + ".reference_roi"));
    spec.reference_roi = ref;
  }
  if (!m.form().empty()) {
    auto model = ParseFormModel(m.form());
    if (!model.ok()) return Status::InvalidArgument(field + ".form: " + model.status().message());
    spec.areal.form.model = *model;
    spec.form.model = *model;
  }
  if (m.form_order() != 0) {
    if (spec.areal.form.model != FormModel::kPolynomial) {
      return Invalid(field + ".form_order", "needs form \"polynomial\"");
    }
    if (m.form_order() < 1 || m.form_order() > 3) return Invalid(field + ".form_order", "must be in [1, 3]");
    spec.areal.form.polynomial_order = m.form_order();
  }
  spec.areal.s_filter_cutoff_um = m.s_filter_um();
  spec.areal.l_filter_cutoff_um = m.l_filter_um();
  if (!m.step_fit().empty()) {
    auto fit = ParseStepHeightFit(m.step_fit());
    if (!fit.ok()) return Status::InvalidArgument(field + ".step_fit: " + fit.status().message());
    spec.step.fit = *fit;
  }
  if (!m.volume_reference().empty()) {
    auto ref = ParseVolumeReference(m.volume_reference());
    if (!ref.ok()) return Status::InvalidArgument(field + ".volume_reference: " + ref.status().message());
    spec.volume.reference = *ref;
  }
  spec.volume.reference_height_um = m.volume_reference_height_um();
  if (m.volume_reference_height_um() != 0 && spec.volume.reference != VolumeReference::kHeight) {
    return Invalid(field + ".volume_reference_height_um", "needs volume_reference \"height\"");
  }
  if (m.volume_unit().empty() || m.volume_unit() == "um3") {
    spec.volume_unit = VolumeUnit::kCubicMicrometre;
  } else if (m.volume_unit() == "mm3") {
    spec.volume_unit = VolumeUnit::kCubicMillimetre;
  } else {
    return Invalid(field + ".volume_unit", "'" + m.volume_unit() + "' is not um3 or mm3");
  }
  return spec;
}

StatusOr<Tolerance> MapTolerance(const v1::RecipeMeasurement& m, const std::string& field) {
  if (!m.has_tolerance()) return Invalid(field + ".tolerance", "is required (nominal and a lower and/or upper limit)");
  const v1::RecipeTolerance& t = m.tolerance();
  Tolerance tol;
  tol.nominal = t.nominal();
  if (t.has_lower()) tol.lower = t.lower();
  if (t.has_upper()) tol.upper = t.upper();
  tol.min_coverage_percent = t.min_coverage_percent();
  INSPECT_RETURN_IF_ERROR(tol.Validate(field + ".tolerance"));
  return tol;
}

}  // namespace

Status CheckRecipeName(const std::string& name, const std::string& field) {
  if (name.empty()) return Invalid(field, "is empty");
  if (name.size() > 64) return Invalid(field, "is " + std::to_string(name.size()) + " characters; at most 64");
  for (char c : name) {
    const bool ok =
        (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '_' || c == '.' || c == '-';
    if (!ok) return Invalid(field, "'" + name + "' may hold only letters, digits, '_', '.' and '-'");
  }
  if (name == "." || name == "..") return Invalid(field, "'" + name + "' is not a name");
  return Status::Ok();
}

Status ValidateRecipe(const v1::Recipe& recipe, cv::Size image_size, double pixel_size_um) {
  const size_t bytes = recipe.ByteSizeLong();
  if (bytes > kMaxRecipeBytes) {
    return Invalid("recipe", "is " + std::to_string(bytes) + " bytes; at most " + std::to_string(kMaxRecipeBytes));
  }
  INSPECT_RETURN_IF_ERROR(CheckRecipeName(recipe.recipe_id(), "recipe.recipe_id"));
  if (recipe.measurements_size() == 0) return Invalid("recipe.measurements", "is empty; a recipe measures something");
  if (recipe.measurements_size() > kMaxRecipeMeasurements) {
    return Invalid("recipe.measurements", "has " + std::to_string(recipe.measurements_size()) + " entries; at most " +
                                              std::to_string(kMaxRecipeMeasurements));
  }
  INSPECT_RETURN_IF_ERROR(MapRecipeMeasurements(recipe, image_size, pixel_size_um).status());
  return MapRecipeProfiles(recipe, image_size, pixel_size_um).status();
}

StatusOr<std::vector<RecipeProfilePlan>> MapRecipeProfiles(const v1::Recipe& recipe, cv::Size image_size,
                                                           double pixel_size_um) {
  if (recipe.profiles_size() > kMaxRecipeProfiles) {
    return Invalid("recipe.profiles", "has " + std::to_string(recipe.profiles_size()) + " entries; at most " +
                                          std::to_string(kMaxRecipeProfiles));
  }
  std::vector<RecipeProfilePlan> plans;
  std::set<std::string> names;
  for (int i = 0; i < recipe.profiles_size(); ++i) {
    const v1::RecipeProfile& p = recipe.profiles(i);
    const std::string field = "recipe.profiles[" + std::to_string(i) + "]";
    INSPECT_RETURN_IF_ERROR(CheckRecipeName(p.name(), field + ".name"));
    if (!names.insert(p.name()).second) return Invalid(field + ".name", "'" + p.name() + "' is used twice");
    RecipeProfilePlan plan;
    plan.name = p.name();
    double to_px = 1.0;
    if (p.unit().empty() || p.unit() == "px") {
      plan.options.unit = RoiUnit::kPixel;
    } else if (p.unit() == "um") {
      plan.options.unit = RoiUnit::kMicrometre;
      to_px = 1.0 / pixel_size_um;
    } else {
      return Invalid(field + ".unit", "'" + p.unit() + "' is not a unit (px or um)");
    }
    if (!std::isfinite(p.width()) || p.width() < 0.0) {
      return Invalid(field + ".width", "must be >= 0 (0 = one pixel)");
    }
    plan.options.start = {p.start().x(), p.start().y()};
    plan.options.end = {p.end().x(), p.end().y()};
    plan.options.width_px = std::max(1.0, p.width() * to_px);
    INSPECT_RETURN_IF_ERROR(plan.options.Validate(image_size, pixel_size_um, field));
    plans.push_back(std::move(plan));
  }
  return plans;
}

StatusOr<std::vector<RecipeMeasurementPlan>> MapRecipeMeasurements(const v1::Recipe& recipe, cv::Size image_size,
                                                                   double pixel_size_um) {
  std::vector<RecipeMeasurementPlan> plans;
  std::set<std::string> names;
  for (int i = 0; i < recipe.measurements_size(); ++i) {
    const v1::RecipeMeasurement& m = recipe.measurements(i);
    const std::string field = "recipe.measurements[" + std::to_string(i) + "]";
    INSPECT_RETURN_IF_ERROR(CheckRecipeName(m.name(), field + ".name"));
    if (!names.insert(m.name()).second) return Invalid(field + ".name", "'" + m.name() + "' is used twice");
    RecipeMeasurementPlan plan;
    plan.name = m.name();
    INSPECT_ASSIGN_OR_RETURN(plan.spec, MapMeasurement(m, field));
    INSPECT_RETURN_IF_ERROR(plan.spec.Validate(image_size, pixel_size_um, field));
    INSPECT_ASSIGN_OR_RETURN(plan.tolerance, MapTolerance(m, field));
    plans.push_back(std::move(plan));
  }
  return plans;
}

v1::ScanRequest ScanRequestOfRecipe(const v1::RecipeScan& scan) {
  v1::ScanRequest r;
  r.set_z_start_um(scan.z_start_um());
  r.set_z_end_um(scan.z_end_um());
  r.set_z_step_um(scan.z_step_um());
  r.set_exposure_us(scan.exposure_us());
  r.set_illumination(scan.illumination());
  *r.mutable_illumination_parameters() = scan.illumination_parameters();
  *r.mutable_reconstruction() = scan.reconstruction();
  if (scan.has_z_range_search()) *r.mutable_z_range_search() = scan.z_range_search();
  return r;
}

}  // namespace inspection
