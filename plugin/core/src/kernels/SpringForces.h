#pragma once
// Spring forces of one muscle (method.md §3–§4), internal.
#include <cstddef>
#include <cstdint>
#include <span>

#include "fibremss/MuscleSettings.h"

namespace fibremss {

/// What one spring-force pass measured.
struct SpringForceResult {
  double deviation = 0;      ///< Σ |l − L0| [m]
  bool exploded = false;     ///< a spring beyond 3× its rest length, or not finite
  size_t overstretched = 0;  ///< springs beyond 3× their rest length, or not finite
  /// springs longer than kStrainWatch·strainLimit times their rest length (0 without a limit):
  /// the iteration's strain-limit pass runs only for a muscle that has one
  size_t nearLimit = 0;
};

/// Share of MuscleSettings::strainLimit beyond which the force kernels count a spring as near the
/// limit (SpringForceResult::nearLimit) [1]: below the limit, so that a spring that one
/// integration carries across it was counted before it.
constexpr btScalar kStrainWatch = btScalar(0.9);

/// The instruction set a spring-force pass runs on.
enum class SpringKernel {
  scalar,  ///< one spring at a time (every build; the only one in the double build)
  sse2,    ///< four springs at a time (float build on x86-64)
  avx2,    ///< eight springs at a time with FMA (float build, CPU with AVX2 and FMA)
};

/// Whether `kernel` runs in this build on this CPU.
bool springKernelAvailable(SpringKernel kernel);

/// The fastest available kernel, or the available one the environment variable
/// FIBREMSS_SPRING_KERNEL names ("scalar", "sse2", "avx2"), chosen once per process:
/// springForces runs it.
SpringKernel fastestSpringKernel();

/// The kernel's name: "scalar", "sse2" or "avx2".
const char* springKernelName(SpringKernel kernel);

/// settings.springs laid out for the AVX2 kernel (SpringBlocks). Throws std::length_error when
/// particle byte offsets do not fit 32 bits.
SpringBlocks springBlocksFor(const MuscleSettings& settings);
/// settings.springBlocks = springBlocksFor(settings). Preparation does it (reorderParticles);
/// MuscleSystem::addMuscle lays out a copy of settings made or changed by hand; the kernel itself
/// only checks the count of springs (else it runs as SSE2).
void layoutSprings(MuscleSettings& settings);

/// F = k·(l − L0)·(x_b − x_a)/l on a, the opposite on b, at `positions` into `forces`
/// (overwritten), in one pass over the springs on fastestSpringKernel() (exact square roots and
/// divisions; SSE2 sums the force on a in a register along the run of springs that share a, AVX2
/// reads settings.springBlocks, two blocks of one a each per group of eight lanes; the kernels
/// differ in rounding only: FMA, order of the sums). Integrators that need forces at other
/// positions (RK, implicit) call this with their buffers.
SpringForceResult springForces(const MuscleSettings& settings, std::span<const btVector3> positions,
                               std::span<btVector3> forces);

/// springForces on the given kernel, which must be available (tests compare the kernels).
SpringForceResult springForces(const MuscleSettings& settings, std::span<const btVector3> positions,
                               std::span<btVector3> forces, SpringKernel kernel);

/// The kernel springForces runs for `kernel` on `settings`: AVX2 only with springBlocks laid out
/// for these springs, else SSE2.
SpringKernel springLayoutKernel(const MuscleSettings& settings, SpringKernel kernel);
/// The length of `kernel`'s layout of the springs: lanes of settings.springBlocks (AVX2), else
/// springs. springForces runs [0, springLayoutSize).
size_t springLayoutSize(const MuscleSettings& settings, SpringKernel kernel);
/// The first index ≥ `index` where a range of `kernel`'s layout may begin or end: a multiple of
/// eight lanes (AVX2), else the first spring of a run of springs that share a; at most the size.
size_t springLayoutBoundary(const MuscleSettings& settings, SpringKernel kernel, size_t index);
/// The forces of the layout's range [begin, end) (boundaries, see springLayoutBoundary) added into
/// `forces` (not zeroed), in the order springForces takes them; what they measured.
SpringForceResult addSpringForces(const MuscleSettings& settings,
                                  std::span<const btVector3> positions, std::span<btVector3> forces,
                                  SpringKernel kernel, size_t begin, size_t end);

/// The forces of the springs `springs` (indices into settings.springs, ascending) added into
/// `forces` (not zeroed), one at a time on the scalar kernel; what they measured. A local step's
/// share of a muscle (MuscleSystem::stepLocal): the same order for any thread count.
SpringForceResult addSpringForces(const MuscleSettings& settings,
                                  std::span<const btVector3> positions, std::span<btVector3> forces,
                                  std::span<const uint32_t> springs);

}  // namespace fibremss
