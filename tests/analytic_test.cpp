// The analytic tier: the cylinder scenes load with their exact case, the measures read known
// deformations of the rest surface back, the exact answers have the limits continuum mechanics
// gives, and a short FibreMSS run measures every figure.
#include "fibremss/Analytic.h"

#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "fibremss/Error.h"
#include "fibremss/FibreRun.h"

namespace fibremss {
namespace {

/// The rest surface moved by `map` (a function of the rest point).
template <typename Map>
std::vector<btVector3> deformed(const TriangleMesh& rest, Map map) {
  std::vector<btVector3> points;
  for (const btVector3& p : rest.vertices) points.push_back(map(p));
  return points;
}

TEST(AnalyticScenes, LoadWithTheirCaseAndSurviveExport) {
  for (const char* name : {"cylinder-stretch", "cylinder-twist"}) {
    const LoadedScene scene = loadScene(name);
    EXPECT_EQ(scene.analytic.type, name);
    EXPECT_NEAR(scene.analytic.axisStart.distance(scene.analytic.axisEnd), 0.1, 1e-6);
    ASSERT_EQ(scene.muscles.size(), 1u);
    EXPECT_GT(scene.poseCount, 1);
    const std::string exported = exportBuiltInScene(name);
    EXPECT_NE(exported.find("\"analytic\""), std::string::npos);
  }
  EXPECT_NEAR(loadScene("cylinder-stretch").analytic.stretch, 1.1, 1e-12);
  EXPECT_NEAR(loadScene("cylinder-twist").analytic.twistDeg, 180, 1e-12);
  EXPECT_EQ(loadScene("fusiform").analytic.type, "none");
}

TEST(AnalyticScenes, RejectUnknownCasesAndDegenerateAxes) {
  EXPECT_THROW(loadScene("cylinder-twist", {"analytic.type=cube"}), InputError);
  EXPECT_THROW(loadScene("cylinder-twist", {"analytic.axis_end=[0,-50,0]"}), InputError);
  EXPECT_THROW(loadScene("cylinder-stretch", {"analytic.poisson_ratio=0.5"}), InputError);
}

TEST(AnalyticExact, NeoHookeanStretchHasTheLinearLimitsAndIsNearlyIncompressibleAtNu049) {
  AnalyticCase small;
  small.type = "cylinder-stretch";
  small.axisStart = btVector3(0, 0, 0);
  small.axisEnd = btVector3(0, 1, 0);
  small.stretch = 1.0001;  // small strain: the effective ν is the material's ν
  for (double nu : {0.0, 0.3, 0.45}) {
    small.poissonRatio = nu;
    EXPECT_NEAR(exactAnalytic(small, {}).exactPoissonRatio, nu, 1e-3) << nu;
  }
  small.poissonRatio = 0.4999;
  small.stretch = 1.1;
  const AnalyticMetrics incompressible = exactAnalytic(small, {});
  EXPECT_NEAR(incompressible.exactPoissonRatio, 0.5, 1e-3);
  EXPECT_NEAR(incompressible.exactMidRadiusRatio, 1 / std::sqrt(1.1), 1e-4);
  small.poissonRatio = 0.49;
  const AnalyticMetrics nearly = exactAnalytic(small, {});
  EXPECT_GT(nearly.exactVolumeChangePct, 0);
  EXPECT_LT(nearly.exactVolumeChangePct, 1);
}

TEST(AnalyticMeasure, HomogeneousStretchReadsBackItsPoissonRatioAndVolume) {
  const LoadedScene scene = loadScene("cylinder-stretch");
  const TriangleMesh& rest = scene.muscles[0].surface;
  const double a = 1.1, s = 0.96;  // axial and lateral stretch about the origin (mid-section)
  const auto moved = deformed(rest, [&](const btVector3& p) {
    return btVector3(btScalar(p.x() * s), btScalar(p.y() * a), btScalar(p.z() * s));
  });
  const AnalyticMetrics m = measureAnalytic(scene.analytic, rest, moved);
  EXPECT_NEAR(m.midRadiusRatio, s, 1e-4);
  EXPECT_NEAR(m.poissonRatio, -std::log(s) / std::log(a), 2e-3);
  EXPECT_NEAR(m.volumeChangePct, 100 * (a * s * s - 1), 0.05);
  EXPECT_TRUE(std::isnan(m.midRotationDeg));
  EXPECT_GT(m.exactPoissonRatio, 0.45);  // the scene's ν = 0.49 continuum
}

TEST(AnalyticMeasure, ExactTorsionHasNoRotationErrorKeepsRadiusAndVolume) {
  const LoadedScene scene = loadScene("cylinder-twist");
  const AnalyticCase& c = scene.analytic;
  const TriangleMesh& rest = scene.muscles[0].surface;
  const btVector3 axis = (c.axisEnd - c.axisStart).normalized();
  const double length = c.axisStart.distance(c.axisEnd);
  const auto twisted = deformed(rest, [&](const btVector3& p) {
    const double t = std::clamp(double((p - c.axisStart).dot(axis)) / length, 0.0, 1.0);
    return quatRotate(btQuaternion(axis, btScalar(t * c.twistDeg * M_PI / 180)), p);
  });
  const AnalyticMetrics m = measureAnalytic(c, rest, twisted);
  EXPECT_NEAR(m.midRotationDeg, 90, 0.01);
  EXPECT_LT(m.rotationErrorDeg, 0.01);
  EXPECT_NEAR(m.midRadiusRatio, 1, 1e-4);
  EXPECT_NEAR(m.volumeChangePct, 0, 0.5);  // the faceted surface's own change under the twist
  // A section that lags is seen: half the twist everywhere puts the 90 % section 72° off.
  const auto half = deformed(rest, [&](const btVector3& p) {
    const double t = std::clamp(double((p - c.axisStart).dot(axis)) / length, 0.0, 1.0);
    return quatRotate(btQuaternion(axis, btScalar(t * c.twistDeg * M_PI / 360)), p);
  });
  EXPECT_NEAR(measureAnalytic(c, rest, half).rotationErrorDeg, 81, 0.5);
}

TEST(AnalyticRun, ShortFibreMSSRunsMeasureEveryFigureAndRoundTripThroughJson) {
  for (const char* name : {"cylinder-stretch", "cylinder-twist"}) {
    const LoadedScene scene =
        loadScene(name, {"resolution=12", "fibre_count=24", "simulation.iterations=300"});
    const PreparedScene prepared = prepareScene(scene.bones, scene.muscles, scene.simulation.seed);
    FibreRunOptions options;
    options.keepPoseSurfaces = false;
    const RunMetrics run = runFibreMSS(scene, prepared, options);
    const AnalyticMetrics& m = run.analytic;
    ASSERT_EQ(m.type, name);
    EXPECT_TRUE(std::isfinite(m.volumeChangePct));
    EXPECT_TRUE(std::isfinite(m.midRadiusRatio));
    if (m.type == "cylinder-stretch") {
      EXPECT_LT(m.midRadiusRatio, 1);  // a stretched cylinder narrows
      EXPECT_GT(m.poissonRatio, 0);
    } else {
      EXPECT_GT(m.midRotationDeg, 45);  // the mid-section follows the twisted end
      EXPECT_LT(m.midRotationDeg, 135);
      EXPECT_TRUE(std::isfinite(m.rotationErrorDeg));
    }
    const AnalyticMetrics back = runMetricsFromJson(toJson(run)).analytic;
    EXPECT_EQ(back.type, m.type);
    EXPECT_DOUBLE_EQ(back.midRadiusRatio, m.midRadiusRatio);
    EXPECT_DOUBLE_EQ(back.exactVolumeChangePct, m.exactVolumeChangePct);
  }
}

}  // namespace
}  // namespace fibremss
