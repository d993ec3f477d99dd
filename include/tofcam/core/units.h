#pragma once
/// \file
/// Physical constants and the register conventions of SwissRanger-style cameras.

#include <cstdint>

namespace tofcam {

/// Speed of light in vacuum, m/s.
inline constexpr double kSpeedOfLightMPerS = 299'792'458.0;
inline constexpr double kPi = 3.14159265358979323846;

/// Unambiguous range L = c / (2 f_mod) in metres (paper eq. 3). 20 MHz gives 7.4948 m; the
/// paper rounds it to 7.5 m. `modulation_frequency_hz` must be > 0.
[[nodiscard]] constexpr double UnambiguousRangeM(double modulation_frequency_hz) noexcept {
  return kSpeedOfLightMPerS / (2.0 * modulation_frequency_hz);
}

/// Distance registers are 16 bit over [0, L): metres = register * L / 65536.
inline constexpr double kDistanceRegisterSpan = 65536.0;
/// Largest amplitude / intensity register value a SwissRanger delivers.
inline constexpr std::uint16_t kMaxSignalRegister = 65532;

}  // namespace tofcam
