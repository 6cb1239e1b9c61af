// Issue 18's coarse-to-fine measurement (a prototype, removed again in the next commit; see
// docs/performance.md, "Coarse-to-fine start"). Per pose, four systems of one scene: `eq` run to
// a mean displacement of 1e-7 m per iteration (compare's `equilibrium`), `base` (the bones move
// over 36 iterations, then blocks of 8 until its surface is within 0.2 mm RMS of eq's), a coarse
// system at the coarse resolution and `fine`, which after the same 36 iterations gets the coarse
// level's correction (nested: the coarse relaxation after its own 36 iterations, interpolated from
// the 4 nearest coarse particles at rest with inverse-distance weights; `fas`: the fine state
// restricted to the coarse level, the restricted fine residual ×scale as a force there, and the
// correction applied with a line search), then the same blocks.
// Usage: coarse_experiment SCENE FINE_R COARSE_R DAMPING_SCALE THREADS CAP COARSE_TOL_MM POSES
//        [fas SCALE]; COARSE_TOL_MM 0: the coarse level runs to 1e-7 m per iteration, else to
// the equilibrium stop rule at that tolerance. Env: COARSE_EXTRA=key=value (one more override),
// COARSE_EQ_ONLY=1 (only the equilibrium runs' iteration counts).
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <string>
#include <vector>

#include "fibremss/MuscleSystem.h"
#include "fibremss/Preparation.h"
#include "fibremss/Scene.h"
#include "solver/MuscleSystemAccess.h"
#include "solver/SpringForces.h"
#include "solver/VolumeForces.h"

using namespace fibremss;

struct Level {
  LoadedScene scene;
  PreparedScene prepared;
  std::unique_ptr<MuscleSystem> sys;
  std::vector<BoneHandle> bones;
  std::vector<MuscleHandle> muscles;
  Level(const std::string& name, std::vector<std::string> overrides)
      : scene(loadScene(name, overrides)),
        prepared(prepareScene(scene.bones, scene.muscles, scene.simulation.seed)) {
    sys = std::make_unique<MuscleSystem>(scene.simulation);
    for (auto& b : prepared.bones) bones.push_back(sys->addBone(b));
    for (auto& m : prepared.muscles) muscles.push_back(sys->addMuscle(m, bones));
  }
  void setPose(int p) {
    for (size_t b = 0; b < bones.size(); ++b) sys->setBoneTransform(bones[b], scene.bonePose(b, p));
  }
  int run(StopRule rule, int iterations, double motionFraction, double eps = 1e-7) {
    auto& prm = sys->parameters();
    prm.stopRule = rule;
    prm.iterations = iterations;
    prm.motionFraction = static_cast<btScalar>(motionFraction);
    prm.epsilon = static_cast<btScalar>(eps);
    sys->step();
    return sys->lastStep().iterations;
  }
  std::vector<btVector3> surfaces() const {
    std::vector<btVector3> out;
    for (auto m : muscles) {
      auto s = sys->surface(m);
      out.insert(out.end(), s.begin(), s.end());
    }
    return out;
  }
  std::vector<btVector3>& positions(size_t m) {
    return MuscleSystemAccess::impl(*sys).muscle(muscles[m]).positions;
  }
  std::vector<btVector3>& previous(size_t m) {
    return MuscleSystemAccess::impl(*sys).muscle(muscles[m]).previous;
  }
};

static double rmsMm(const std::vector<btVector3>& a, const std::vector<btVector3>& b, double unit) {
  double s = 0;
  for (size_t i = 0; i < a.size(); ++i) s += (a[i] - b[i]).length2();
  return std::sqrt(s / a.size()) / unit;
}

struct Weights {
  std::vector<uint32_t> idx;
  std::vector<btScalar> w;
};
static constexpr int K = 4;
static Weights weightsFor(const MuscleSettings& fine, const MuscleSettings& coarse) {
  Weights W;
  for (size_t i = 0; i < fine.particleCount(); ++i) {
    uint32_t best[K];
    double bd[K];
    for (int k = 0; k < K; ++k) bd[k] = 1e30, best[k] = 0;
    for (uint32_t j = 0; j < coarse.particleCount(); ++j) {
      double d = (fine.restPositions[i] - coarse.restPositions[j]).length2();
      if (d < bd[K - 1]) {
        int k = K - 1;
        while (k > 0 && bd[k - 1] > d) bd[k] = bd[k - 1], best[k] = best[k - 1], --k;
        bd[k] = d, best[k] = j;
      }
    }
    double sum = 0, ww[K];
    for (int k = 0; k < K; ++k) sum += ww[k] = 1 / (std::sqrt(bd[k]) + 1e-5);
    for (int k = 0; k < K; ++k) W.idx.push_back(best[k]), W.w.push_back(btScalar(ww[k] / sum));
  }
  return W;
}

static double gCoarseTol = 0;
static btScalar gScale = 1;
static int relaxCoarse(Level& coarse) {
  if (gCoarseTol > 0) coarse.sys->parameters().tolerance = btScalar(gCoarseTol * 1e-3);
  return coarse.run(gCoarseTol > 0 ? StopRule::Equilibrium : StopRule::Converged, 20000, 0.5, 1e-7);
}

static void modelForces(const MuscleSettings& s, const std::vector<btVector3>& x,
                        std::vector<btVector3>& f) {
  f.assign(x.size(), btVector3(0, 0, 0));
  springForces(s, x, f);
  addTetrahedronForces(s, x, f);
}

// FAS-style coarse correction: restrict the fine state, add tau, relax the coarse, prolong the
// correction with a line search along it.
static int fasCorrection(Level& fine, Level& coarse, const std::vector<Weights>& P,
                         const std::vector<Weights>& R, double& alphaOut) {
  const size_t M = fine.muscles.size();
  std::vector<std::vector<btVector3>> xc0(M), ff(M);
  for (size_t m = 0; m < M; ++m) {
    const MuscleSettings& fs = *fine.prepared.muscles[m];
    const MuscleSettings& cs = *coarse.prepared.muscles[m];
    auto& xf = fine.positions(m);
    auto& xc = coarse.positions(m);
    auto& pc = coarse.previous(m);
    for (uint32_t j = 0; j < cs.particleCount(); ++j) {
      if (cs.isFixed(j)) continue;
      btVector3 d(0, 0, 0);
      for (int k = 0; k < K; ++k) {
        uint32_t i = R[m].idx[j * K + k];
        d += R[m].w[j * K + k] * (xf[i] - fs.restPositions[i]);
      }
      xc[j] = cs.restPositions[j] + d;
      pc[j] = xc[j];
    }
    modelForces(fs, xf, ff[m]);
    std::vector<btVector3> fc, rf(cs.particleCount(), btVector3(0, 0, 0));
    modelForces(cs, xc, fc);
    for (uint32_t i = 0; i < fs.particleCount(); ++i) {
      if (fs.isFixed(i)) continue;
      for (int k = 0; k < K; ++k) rf[P[m].idx[i * K + k]] += P[m].w[i * K + k] * ff[m][i];
    }
    for (uint32_t j = 0; j < cs.particleCount(); ++j)
      if (!cs.isFixed(j))
        coarse.sys->setExternalForce(coarse.muscles[m], j, gScale * rf[j] - fc[j]);
    xc0[m] = xc;
  }
  int it = relaxCoarse(coarse);
  double num = 0, den = 0;
  std::vector<std::vector<btVector3>> v(M);
  for (size_t m = 0; m < M; ++m) {
    const MuscleSettings& fs = *fine.prepared.muscles[m];
    const MuscleSettings& cs = *coarse.prepared.muscles[m];
    coarse.sys->clearExternalForces(coarse.muscles[m]);
    auto& xc = coarse.positions(m);
    auto& xf = fine.positions(m);
    v[m].assign(fs.particleCount(), btVector3(0, 0, 0));
    for (uint32_t i = 0; i < fs.particleCount(); ++i) {
      if (fs.isFixed(i)) continue;
      for (int k = 0; k < K; ++k) {
        uint32_t j = P[m].idx[i * K + k];
        v[m][i] += P[m].w[i * K + k] * (xc[j] - xc0[m][j]);
      }
    }
    (void)cs;
    const btScalar eps = btScalar(1e-2);
    std::vector<btVector3> xe(xf), fe;
    for (uint32_t i = 0; i < fs.particleCount(); ++i) xe[i] += eps * v[m][i];
    modelForces(fs, xe, fe);
    for (uint32_t i = 0; i < fs.particleCount(); ++i) {
      if (fs.isFixed(i)) continue;
      num += v[m][i].dot(ff[m][i]);
      den += -v[m][i].dot(fe[i] - ff[m][i]) / eps;
    }
  }
  double alpha = den > 0 ? num / den : 1;
  alphaOut = alpha;
  if (!(alpha > 0) || alpha > 2) alpha = 1;
  for (size_t m = 0; m < M; ++m) {
    auto& xf = fine.positions(m);
    auto& pf = fine.previous(m);
    for (size_t i = 0; i < xf.size(); ++i) {
      xf[i] += btScalar(alpha) * v[m][i];
      if (!fine.prepared.muscles[m]->isFixed(uint32_t(i))) pf[i] = xf[i];
    }
  }
  return it;
}

int main(int argc, char** argv) {
  const std::string name = argc > 1 ? argv[1] : "fusiform";
  const int fineR = argc > 2 ? std::atoi(argv[2]) : 40;
  const int coarseR = argc > 3 ? std::atoi(argv[3]) : 10;
  const std::string damping = argc > 4 ? argv[4] : "0.5";
  const int threads = argc > 5 ? std::atoi(argv[5]) : 1;
  const int motion = 36, block = 8, cap = argc > 6 ? std::atoi(argv[6]) : 4000;
  gCoarseTol = argc > 7 ? std::atof(argv[7]) : 0;  // mm; 0: converged 1e-7
  auto ov = [&](int r) {
    std::vector<std::string> o{"resolution=" + std::to_string(r),
                               "threads=" + std::to_string(threads), "damping_scale=" + damping};
    if (const char* extra = std::getenv("COARSE_EXTRA")) o.push_back(extra);
    return o;
  };
  Level eq(name, ov(fineR)), base(name, ov(fineR)), fine(name, ov(fineR)),
      coarse(name, ov(coarseR));
  const double unit = 1e-3;
  size_t fineParticles = 0, coarseParticles = 0;
  std::vector<Weights> W, Rw;
  const bool fas = argc > 9 && std::string(argv[9]) == "fas";
  if (argc > 10) gScale = btScalar(std::atof(argv[10]));
  for (size_t m = 0; m < fine.muscles.size(); ++m) {
    fineParticles += fine.prepared.muscles[m]->particleCount();
    coarseParticles += coarse.prepared.muscles[m]->particleCount();
    W.push_back(weightsFor(*fine.prepared.muscles[m], *coarse.prepared.muscles[m]));
    if (fas) Rw.push_back(weightsFor(*coarse.prepared.muscles[m], *fine.prepared.muscles[m]));
  }
  std::printf("%s fine R=%d (%zu particles) coarse R=%d (%zu) damping %s poses %d\n", name.c_str(),
              fineR, fineParticles, coarseR, coarseParticles, damping.c_str(), eq.scene.poseCount);
  const int poses = argc > 8 ? std::atoi(argv[8]) : eq.scene.poseCount;
  for (int p = 0; p < poses; ++p) {
    eq.setPose(p);
    int eqIt = eq.run(StopRule::Converged, 20000, double(motion) / 20000);
    auto target = eq.surfaces();
    if (std::getenv("COARSE_DT")) {
      auto& impl = MuscleSystemAccess::impl(*eq.sys);
      std::printf("dt %.3g:", double(eq.sys->lastStep().lastTimeStep));
      for (size_t m = 0; m < eq.muscles.size(); ++m)
        std::printf(" %s %.3g (%zu)", eq.prepared.muscles[m]->name.c_str(),
                    double(impl.results[eq.muscles[m].index].safeTimeStep),
                    eq.prepared.muscles[m]->particleCount());
      std::printf("\n");
    }
    if (std::getenv("COARSE_EQ_ONLY")) {
      std::printf("pose %d: eq %d it\n", p, eqIt);
      std::fflush(stdout);
      continue;
    }
    // Baseline: motion, then blocks until within 0.5 mm.
    base.setPose(p);
    base.run(StopRule::Iterations, motion, 1.0);
    int bIt = motion, b05 = -1, b02 = -1;
    double bStart = rmsMm(base.surfaces(), target, unit);
    while (bIt < cap && b02 < 0) {
      double d = rmsMm(base.surfaces(), target, unit);
      if (d <= 0.5 && b05 < 0) b05 = bIt;
      if (d <= 0.2) b02 = bIt;
      if (b02 >= 0) break;
      bIt += base.run(StopRule::Iterations, block, 1.0);
    }
    coarse.setPose(p);
    coarse.run(StopRule::Iterations, motion, 1.0);
    std::vector<std::vector<btVector3>> before;
    for (size_t m = 0; m < coarse.muscles.size(); ++m) before.push_back(coarse.positions(m));
    int cIt = motion;
    double coarseToEq = 0, alpha = 0;
    fine.setPose(p);
    fine.run(StopRule::Iterations, motion, 1.0);
    double fStart0 = rmsMm(fine.surfaces(), target, unit);
    if (fas) {
      cIt += fasCorrection(fine, coarse, W, Rw, alpha);
    } else {
      cIt += relaxCoarse(coarse);
      coarseToEq = rmsMm(coarse.surfaces(), target, unit);
      for (size_t m = 0; m < fine.muscles.size(); ++m) {
        const MuscleSettings& s = *fine.prepared.muscles[m];
        auto& x = fine.positions(m);
        auto& xp = fine.previous(m);
        const auto& cx = coarse.positions(m);
        for (uint32_t i = 0; i < s.particleCount(); ++i) {
          if (s.isFixed(i)) continue;
          btVector3 d(0, 0, 0);
          for (int k = 0; k < K; ++k) {
            uint32_t j = W[m].idx[i * K + k];
            d += W[m].w[i * K + k] * (cx[j] - before[m][j]);
          }
          x[i] += d;
          xp[i] = x[i];
        }
      }
    }
    fine.run(StopRule::Iterations, 1, 1.0);  // refresh the surface (one iteration)
    int fIt = motion + 1, f05 = -1, f02 = -1;
    double fStart = rmsMm(fine.surfaces(), target, unit);
    while (fIt < cap) {
      double d = rmsMm(fine.surfaces(), target, unit);
      if (d <= 0.5 && f05 < 0) f05 = fIt;
      if (d <= 0.2) f02 = fIt;
      if (f02 >= 0) break;
      fIt += fine.run(StopRule::Iterations, block, 1.0);
    }
    std::printf(
        "pose %d: eq %d it | base start %.3f mm, to 0.5mm %d it, to 0.2mm %d | coarse %d it, "
        "coarse "
        "eq to fine eq %.3f mm alpha %.3f (fine-equivalent %d it) | c2f start %.3f (before corr "
        "%.3f) mm, to 0.5mm %d it, to 0.2mm %d\n",
        p, eqIt, bStart, b05, b02, cIt, coarseToEq, alpha,
        int(cIt * double(coarseParticles) / fineParticles), fStart, fStart0, f05, f02);
    std::fflush(stdout);
  }
}
