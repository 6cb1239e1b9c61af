#include "fibremss/Kernel.h"

#include "SpringForces.h"

namespace fibremss {

const char* activeSpringKernel() {
  return springKernelName(fastestSpringKernel());
}

}  // namespace fibremss
