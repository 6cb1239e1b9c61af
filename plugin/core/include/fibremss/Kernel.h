#pragma once
// Which instruction set the solver's spring forces run on in this process, for version and
// benchmark reports.

namespace fibremss {

/// "avx2", "sse2" or "scalar": the fastest spring-force kernel this build and this CPU have
/// (AVX2 needs AVX2 and FMA at runtime; a double build has only scalar), or the available one the
/// environment variable FIBREMSS_SPRING_KERNEL names. Chosen once per process.
const char* activeSpringKernel();

}  // namespace fibremss
