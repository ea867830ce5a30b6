#include "common/world/noise.h"

namespace terrane {

float fbm2(double x, double z, std::uint32_t seed, int octaves) {
  float sum = 0.0f, amplitude = 1.0f, total = 0.0f;
  double frequency = 1.0;
  for (int i = 0; i < octaves; ++i) {
    sum += amplitude * gradient_noise2(x * frequency, z * frequency, hash_u32(seed + static_cast<std::uint32_t>(i)));
    total += amplitude;
    amplitude *= 0.5f;
    frequency *= 2.0;
  }
  return sum / total;
}

float fbm3(double x, double y, double z, std::uint32_t seed, int octaves) {
  float sum = 0.0f, amplitude = 1.0f, total = 0.0f;
  double frequency = 1.0;
  for (int i = 0; i < octaves; ++i) {
    sum += amplitude * gradient_noise3(x * frequency, y * frequency, z * frequency,
                                       hash_u32(seed + static_cast<std::uint32_t>(i)));
    total += amplitude;
    amplitude *= 0.5f;
    frequency *= 2.0;
  }
  return sum / total;
}

float ridged2(double x, double z, std::uint32_t seed, int octaves) {
  float sum = 0.0f, amplitude = 1.0f, total = 0.0f, weight = 1.0f;
  double frequency = 1.0;
  for (int i = 0; i < octaves; ++i) {
    float n = gradient_noise2(x * frequency, z * frequency, hash_u32(seed + static_cast<std::uint32_t>(i)));
    n = 1.0f - (n < 0.0f ? -n : n);
    n *= n;
    sum += n * amplitude * weight;
    total += amplitude;
    weight = clampf(n * 1.5f, 0.0f, 1.0f);
    amplitude *= 0.5f;
    frequency *= 2.0;
  }
  return sum / total;
}

}  // namespace terrane
