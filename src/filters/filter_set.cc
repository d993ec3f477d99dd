#include "tofcam/filters/filter_set.h"

#include <memory>
#include <utility>

#include "../pipeline/stage_kernels.h"
#include "filter_internal.h"
#include "tofcam/core/error.h"

namespace tofcam {
namespace {

// prior = frame flags | raised so far: what the next neighbourhood filter must ignore.
void Combine(const MetricFrame& frame, const Image<PixelFlags>& raised, Image<PixelFlags>& prior) {
  const PixelFlags* r = raised.data();
  PixelFlags* p = prior.data();
  if (frame.flags.empty()) {
    for (std::size_t i = 0; i < raised.size(); ++i) p[i] = r[i];
    return;
  }
  const PixelFlags* f = frame.flags.data();
  for (std::size_t i = 0; i < raised.size(); ++i) p[i] = f[i] | r[i];
}

}  // namespace

void FilterSetOptions::Validate() const {
  if (range_enabled) range.Validate();
  if (amplitude_enabled) amplitude.Validate();
  if (saturation_enabled) saturation.Validate();
  if (accuracy_enabled) accuracy.Validate();
  if (confidence_enabled) confidence.Validate();
  if (flying_pixel_enabled) flying_pixel.Validate();
  if (jump_edge_enabled) jump_edge.Validate();
  if (weingarten_enabled) weingarten.Validate();
}

namespace filters_internal {

PreparedRays PrepareRays(const RayTable& rays, const FilterSetOptions& o) {
  PreparedRays p;
  if (o.jump_edge_enabled) p.lambdas = MakeJumpLambdas(rays, o.jump_edge.max_angle_deg);
  if (o.weingarten_enabled) p.bounds = MakeRayBounds(rays);
  return p;
}

void NeighbourhoodFiltersInto(const MetricFrame& frame, const RayTable& rays,
                              const PreparedRays* prepared, const FilterSetOptions& o,
                              Image<PixelFlags>& raised, bool nothing_raised) {
  const int enabled = static_cast<int>(o.flying_pixel_enabled) +
                      static_cast<int>(o.jump_edge_enabled) +
                      static_cast<int>(o.weingarten_enabled);
  if (enabled == 0) return;
  // What each filter treats as already rejected: frame flags | raised so far. One filter after
  // nothing reads the frame's own flags in place (as the single-filter functions do). Otherwise
  // a per-thread scratch image holds the union, combined once and kept so by the flying-pixel
  // and jump-edge filters, which echo their bits into it (cheaper than combining the two images
  // again before each filter); no allocation once the frame size is stable.
  const Image<PixelFlags>* prior = &frame.flags;
  Image<PixelFlags>* echo = nullptr;
  if (!(nothing_raised && enabled == 1)) {
    thread_local Image<PixelFlags> scratch;
    if (!scratch.SameSize(raised)) scratch = Image<PixelFlags>(raised.width(), raised.height());
    Combine(frame, raised, scratch);
    prior = echo = &scratch;
  }
  if (o.flying_pixel_enabled) FlyingPixelInto(frame, *prior, o.flying_pixel, raised, echo);
  if (o.jump_edge_enabled) {
    if (prepared != nullptr && prepared->lambdas) {
      JumpEdgeInto(frame, *prior, *prepared->lambdas, raised, echo);
    } else {
      JumpEdgeInto(frame, *prior, rays, o.jump_edge, raised, echo);
    }
  }
  if (o.weingarten_enabled) {
    if (prepared != nullptr) {
      WeingartenInto(frame, *prior, rays, prepared->bounds, o.weingarten, raised);
    } else {
      WeingartenInto(frame, *prior, rays, o.weingarten, raised);
    }
  }
}

}  // namespace filters_internal

namespace {

// ApplyFiltersInto after its options were validated; `prepared` as in NeighbourhoodFiltersInto.
void RunFilters(const MetricFrame& frame, const RayTable& rays,
                const filters_internal::PreparedRays* prepared, const FilterSetOptions& o,
                Image<PixelFlags>& out) {
  namespace fi = filters_internal;
  fi::CheckFrame(frame, "filters");
  if (o.jump_edge_enabled || o.weingarten_enabled) fi::CheckRays(frame, rays, "filters");
  const kernels::PixelFilterPlan plan = kernels::PreparePixelFilters(frame, o);
  if (!out.SameSize(frame.radial_distance_m))
    out = Image<PixelFlags>(frame.width(), frame.height());
  auto data = [](const Image<float>& c) { return c.empty() ? nullptr : c.data(); };
  kernels::PixelFiltersSpan(plan, out.size(), frame.radial_distance_m.data(), data(frame.amplitude),
                            data(frame.intensity), data(frame.delta_l_m), out.data());
  if (o.confidence_enabled) ConfidenceThresholdInto(frame, o.confidence, out);
  fi::NeighbourhoodFiltersInto(frame, rays, prepared, o, out,
                               /*nothing_raised=*/!plan.any && !o.confidence_enabled);
}

}  // namespace

void ApplyFiltersInto(const MetricFrame& frame, const RayTable& rays, const FilterSetOptions& o,
                      Image<PixelFlags>& out) {
  o.Validate();
  RunFilters(frame, rays, nullptr, o, out);
}

struct FilterSet::Prepared {
  FilterSetOptions options;
  RayTable rays;
  filters_internal::PreparedRays derived;
};

FilterSet::FilterSet(FilterSetOptions options, RayTable rays) {
  options.Validate();
  if (!rays.x.SameSize(rays.y) || !rays.x.SameSize(rays.z)) {
    throw Error(ErrorCode::kMismatch, "filters: the ray table's x, y and z images differ in size");
  }
  filters_internal::PreparedRays derived = filters_internal::PrepareRays(rays, options);
  prepared_ = std::make_shared<const Prepared>(
      Prepared{std::move(options), std::move(rays), std::move(derived)});
}

void FilterSet::Process(const MetricFrame& frame, Image<PixelFlags>& out) const {
  const Prepared& p = Get();
  RunFilters(frame, p.rays, &p.derived, p.options, out);
}

const FilterSetOptions& FilterSet::options() const { return Get().options; }

const RayTable& FilterSet::rays() const { return Get().rays; }

const FilterSet::Prepared& FilterSet::Get() const {
  if (!prepared_) throw Error(ErrorCode::kInvalidArgument, "filters: FilterSet used after a move");
  return *prepared_;
}

Image<PixelFlags> FilterSet::Process(const MetricFrame& frame) const {
  Image<PixelFlags> out;
  Process(frame, out);
  return out;
}

Image<PixelFlags> ApplyFilters(const MetricFrame& frame, const RayTable& rays,
                               const FilterSetOptions& o) {
  Image<PixelFlags> raised;
  ApplyFiltersInto(frame, rays, o, raised);
  return raised;
}

}  // namespace tofcam
