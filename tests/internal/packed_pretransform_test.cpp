// The blended pre-transform's vector paths (method.md §4): the packed SSE2 transform and the
// AVX2 one that moves x and x(t−dt) of a particle in one register give each point the bits of
// the scalar pretransformPoint.
#include <gtest/gtest.h>

#include <cstring>
#include <random>
#include <vector>

#include "fibremss/Pretransform.h"
#include "kernels/MuscleSystemPretransform.h"
#include "kernels/SpringForces.h"

namespace fibremss {
namespace {

TEST(PackedPretransform, EveryPathGivesTheScalarBlendBitForBit) {
  // Particles blended between two of three bones (weights 0, 1 and between; no bone, and a bone
  // beyond the transforms), bones rotated and moved; w lanes of the points set, as the packed
  // paths keep them.
#if !FIBREMSS_SSE_PRETRANSFORM
  GTEST_SKIP() << "no packed pre-transform in this build (double or without SSE2)";
#else
  const auto same = [](const btVector3& a, const btVector3& b) {
    return std::memcmp(a.m_floats, b.m_floats, sizeof(a.m_floats)) == 0;
  };
  std::mt19937 random(31);
  std::uniform_real_distribution<double> uniform(-1, 1);
  const auto draw = [&](double scale) {
    btVector3 v;
    for (int axis = 0; axis < 4; ++axis) v.m_floats[axis] = btScalar(scale * uniform(random));
    return v;
  };
  constexpr uint32_t kParticles = 200;
  constexpr size_t kBones = 3;
  MuscleSettings settings;
  for (uint32_t i = 0; i < kParticles; ++i) {
    const int kind = static_cast<int>(i % 5);
    settings.blendWeight.push_back(kind == 0   ? 0
                                   : kind == 1 ? 1
                                               : btScalar(0.5 + uniform(random) / 2));
    settings.blendBoneA.push_back(static_cast<int32_t>(i % 4) - (i % 7 == 0 ? 2 : 0));
    settings.blendBoneB.push_back(static_cast<int32_t>((i / 3) % 4));
  }
  std::vector<btTransform> deltas;
  for (size_t b = 0; b < kBones; ++b) {
    const btVector3 axis = draw(1);
    deltas.emplace_back(btQuaternion(btVector3(axis.x(), axis.y(), axis.z()).normalized(),
                                     btScalar(0.1 * uniform(random))),
                        draw(0.01));
  }
  std::vector<btVector3> x, y;
  for (uint32_t i = 0; i < kParticles; ++i) {
    x.push_back(draw(0.2));
    y.push_back(x.back() + draw(1e-4));
  }
  std::vector<uint32_t> particles;
  for (uint32_t i = 0; i < kParticles; i += 1 + i % 3) particles.push_back(i);

  std::vector<btVector3> expectedX = x, expectedY = y;
  for (uint32_t i : particles) {
    expectedX[i] = pretransformPoint(settings, deltas, i, x[i], true, PretransformBlend::Linear);
    expectedY[i] = pretransformPoint(settings, deltas, i, y[i], true, PretransformBlend::Linear);
  }
  PackedTransform packed[kBones];
  for (size_t b = 0; b < kBones; ++b) packed[b] = packTransform(deltas[b]);

  std::vector<btVector3> sseX = x, sseY = y;
  for (uint32_t i : particles) pretransformPacked(settings, packed, kBones, i, sseX[i], sseY[i]);
  size_t moved = 0;
  for (uint32_t i = 0; i < kParticles; ++i) {
    EXPECT_TRUE(same(sseX[i], expectedX[i])) << "SSE2, x of particle " << i;
    EXPECT_TRUE(same(sseY[i], expectedY[i])) << "SSE2, previous of particle " << i;
    moved += !same(expectedX[i], x[i]);
  }
  EXPECT_GT(moved, particles.size() / 2);

#if FIBREMSS_AVX2_PARTICLES
  if (!springKernelAvailable(SpringKernel::avx2)) GTEST_SKIP() << "no AVX2 on this CPU";
  std::vector<btVector3> avxX = x, avxY = y;
  pretransformPackedAvx2(settings, packed, kBones, particles, avxX.data(), avxY.data());
  for (uint32_t i = 0; i < kParticles; ++i) {
    EXPECT_TRUE(same(avxX[i], expectedX[i])) << "AVX2, x of particle " << i;
    EXPECT_TRUE(same(avxY[i], expectedY[i])) << "AVX2, previous of particle " << i;
  }
#endif
#endif
}

}  // namespace
}  // namespace fibremss
