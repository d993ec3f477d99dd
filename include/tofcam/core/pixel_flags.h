#pragma once
/// \file
/// Per-pixel problem flags as a 16-bit bit field. A pixel is usable when none of the
/// "reject" bits is set; there are no magic distance values anywhere in tofcam.

#include <cstdint>
#include <string>
#include <string_view>

namespace tofcam {

/// One problem a pixel can have. The same bits serve the pipeline (what a filter decided) and
/// the simulator's ground truth (what physically happened to the pixel).
enum class Flag : std::uint16_t {
  kInvalid = 1u << 0,       ///< No usable measurement at all (e.g. zero amplitude, import gap).
  kSaturated = 1u << 1,     ///< At least one tap clipped at full well.
  kLowAmplitude = 1u << 2,  ///< Amplitude below the amplitude threshold.
  kHighDeltaL = 1u << 3,    ///< Predicted inaccuracy ΔL (eq. 2) above the threshold.
  kJumpEdge = 1u << 4,      ///< Removed by the jump-edge filter (May et al.).
  kFlyingPixel = 1u << 5,   ///< Removed by the edge-aware flying-pixel filter.
  kOutOfRange = 1u << 6,    ///< Distance outside the configured range limits.
  kBeyondUnambiguous = 1u << 7,  ///< Truth: the surface lies beyond the unambiguous range L.
  kSparseCell = 1u << 8,         ///< Removed by the Weingarten cell filter.
  kMixed = 1u << 9,              ///< Truth: the pixel footprint straddles a depth edge.
  kMultipath = 1u << 10,   ///< Truth: a secondary (mirror / inter-reflection) path contributes.
  kScattering = 1u << 11,  ///< Truth: in-camera scattering dominates the pixel's error.
  kNoReturn = 1u << 12,    ///< Truth: the ray hits nothing (open sky / beyond the scene).
  kMotion = 1u << 13,      ///< Truth: taps disagree because the scene moved during exposure.
  /// Two measurements of the pixel disagree beyond their predicted σ (two modulation
  /// frequencies that do not unwrap to one distance, HDR exposures that differ: motion or
  /// multipath).
  kInconsistent = 1u << 14,
  /// Rejected by a confidence threshold: a camera's own confidence channel or tofcam's
  /// combined per-pixel confidence.
  kLowConfidence = 1u << 15,
};

/// All flags set by pipeline filters: a pixel with any of these is rejected.
/// The 16 bits are all assigned; a new flag means widening PixelFlags (a recording-format change).
inline constexpr std::uint16_t kRejectMask =
    0xC17F;  // kInvalid..kOutOfRange | kSparseCell | kInconsistent | kLowConfidence
/// All ground-truth cause bits.
inline constexpr std::uint16_t kTruthMask = 0x3E82;

/// A 16-bit set of Flag values. Trivially copyable, two bytes, so Image<PixelFlags> is as cheap
/// as Image<uint16_t>.
class PixelFlags {
 public:
  constexpr PixelFlags() noexcept = default;
  constexpr explicit PixelFlags(std::uint16_t bits) noexcept : bits_(bits) {}
  constexpr PixelFlags(Flag flag) noexcept  // NOLINT(google-explicit-constructor)
      : bits_(static_cast<std::uint16_t>(flag)) {}

  [[nodiscard]] constexpr std::uint16_t bits() const noexcept { return bits_; }
  [[nodiscard]] constexpr bool Has(Flag flag) const noexcept {
    return (bits_ & static_cast<std::uint16_t>(flag)) != 0;
  }
  /// True when any bit of `mask` is set.
  [[nodiscard]] constexpr bool Any(std::uint16_t mask) const noexcept {
    return (bits_ & mask) != 0;
  }
  [[nodiscard]] constexpr bool None() const noexcept { return bits_ == 0; }
  /// True when no reject bit (kRejectMask) is set: the pixel may be used.
  [[nodiscard]] constexpr bool Valid() const noexcept { return (bits_ & kRejectMask) == 0; }

  constexpr PixelFlags& Set(Flag flag) noexcept {
    bits_ = static_cast<std::uint16_t>(bits_ | static_cast<std::uint16_t>(flag));
    return *this;
  }
  constexpr PixelFlags& Clear(Flag flag) noexcept {
    bits_ = static_cast<std::uint16_t>(bits_ & ~static_cast<std::uint16_t>(flag));
    return *this;
  }
  constexpr PixelFlags& operator|=(PixelFlags other) noexcept {
    bits_ = static_cast<std::uint16_t>(bits_ | other.bits_);
    return *this;
  }
  friend constexpr PixelFlags operator|(PixelFlags a, PixelFlags b) noexcept { return a |= b; }
  friend constexpr PixelFlags operator&(PixelFlags a, PixelFlags b) noexcept {
    return PixelFlags(static_cast<std::uint16_t>(a.bits_ & b.bits_));
  }
  friend constexpr bool operator==(PixelFlags a, PixelFlags b) noexcept {
    return a.bits_ == b.bits_;
  }

 private:
  std::uint16_t bits_ = 0;
};

static_assert(sizeof(PixelFlags) == 2);

/// Stable lower-case name of one flag, e.g. "high-delta-l".
[[nodiscard]] std::string_view FlagName(Flag flag) noexcept;
/// Names of all set bits joined with '|', or "none".
[[nodiscard]] std::string FlagsToString(PixelFlags flags);
/// Parses a name from FlagName(); throws Error(kInvalidArgument) naming the unknown flag.
[[nodiscard]] Flag ParseFlag(std::string_view name);

/// Every Flag value in bit order, for iteration.
inline constexpr Flag kAllFlags[] = {
    Flag::kInvalid,    Flag::kSaturated,   Flag::kLowAmplitude, Flag::kHighDeltaL,
    Flag::kJumpEdge,   Flag::kFlyingPixel, Flag::kOutOfRange,   Flag::kBeyondUnambiguous,
    Flag::kSparseCell, Flag::kMixed,       Flag::kMultipath,    Flag::kScattering,
    Flag::kNoReturn,   Flag::kMotion,      Flag::kInconsistent, Flag::kLowConfidence};

}  // namespace tofcam
