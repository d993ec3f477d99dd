#include "tofcam/filters/filter_set.h"

#include "filter_internal.h"

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
  if (flying_pixel_enabled) flying_pixel.Validate();
  if (jump_edge_enabled) jump_edge.Validate();
  if (weingarten_enabled) weingarten.Validate();
}

Image<PixelFlags> ApplyFilters(const MetricFrame& frame, const RayTable& rays,
                               const FilterSetOptions& o) {
  namespace fi = filters_internal;
  o.Validate();
  fi::CheckFrame(frame, "filters");
  if (o.jump_edge_enabled || o.weingarten_enabled) fi::CheckRays(frame, rays, "filters");
  Image<PixelFlags> raised(frame.width(), frame.height());
  fi::PixelFilterSet pixel;
  if (o.range_enabled) pixel.range = &o.range;
  if (o.amplitude_enabled) pixel.amplitude = &o.amplitude;
  if (o.saturation_enabled) pixel.saturation = &o.saturation;
  if (o.accuracy_enabled) pixel.accuracy = &o.accuracy;
  fi::PixelFiltersInto(frame, pixel, raised);
  if (!o.flying_pixel_enabled && !o.jump_edge_enabled && !o.weingarten_enabled) return raised;

  // One scratch image for the combined flags, refreshed before each neighbourhood filter.
  Image<PixelFlags> prior(frame.width(), frame.height());
  if (o.flying_pixel_enabled) {
    Combine(frame, raised, prior);
    fi::FlyingPixelInto(frame, prior, o.flying_pixel, raised);
  }
  if (o.jump_edge_enabled) {
    Combine(frame, raised, prior);
    fi::JumpEdgeInto(frame, prior, rays, o.jump_edge, raised);
  }
  if (o.weingarten_enabled) {
    Combine(frame, raised, prior);
    fi::WeingartenInto(frame, prior, rays, o.weingarten, raised);
  }
  return raised;
}

}  // namespace tofcam
