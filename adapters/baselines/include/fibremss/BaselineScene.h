#pragma once
// What the comparison runner steps and measures of a baseline simulator (the btSoftBody
// baseline, Bullet's FEM): one pose at a time, its nodes, its muscles' surfaces and the node
// pairs its explosion rule checks.
#include <LinearMath/btTransform.h>

#include <cstdint>
#include <functional>
#include <span>
#include <string>
#include <vector>

namespace fibremss {

/// Two nodes of one muscle and their rest distance, checked against the guard's explosion rule.
struct NodePair {
  uint32_t a = 0;           ///< first node (index into nodePositions)
  uint32_t b = 0;           ///< second node
  btScalar restLength = 0;  ///< their rest distance [m]
};

/// A baseline simulation of a prepared scene, stepped pose by pose.
class BaselineScene {
 public:
  virtual ~BaselineScene() = default;

  /// One pose: bones move to `targets`. Returns false when `stop` (checked between substeps
  /// where the simulator can; may be empty) ended the pose early.
  virtual bool stepPose(std::span<const btTransform> targets,
                        const std::function<bool()>& stop = {}) = 0;
  /// How many muscles it simulates (the prepared scene's, in order).
  virtual size_t muscleCount() const = 0;
  /// Nodes of all muscles.
  virtual size_t nodeCount() const = 0;
  /// Its elements of all muscles: links of a spring model, tetrahedra of a continuum.
  virtual size_t elementCount() const = 0;
  /// Nodes that are the muscles' boundary particles (0 for a mesh of its own).
  virtual size_t boundaryNodeCount() const = 0;
  /// Node positions of one muscle, as of the last step [m].
  virtual std::span<const btVector3> nodePositions(size_t muscle) const = 0;
  /// The muscle's deformed surface vertices, in the prepared surface's order [m].
  virtual void surface(size_t muscle, std::vector<btVector3>& out) const = 0;
  /// The node pairs of one muscle the explosion rule checks.
  virtual std::vector<NodePair> nodePairs(size_t muscle) const = 0;
  /// Σ|l − L0| / Σ L0 over the springs now; NaN for a model without springs.
  virtual double springDeviation() const = 0;
  /// Solver iterations of one pose (for ms per iteration).
  virtual long iterationsPerPose() const = 0;
  /// World substeps of one pose (for ms per time step).
  virtual long substepsPerPose() const = 0;
  /// Its solver and settings in one line, with what happened in the poses stepped so far.
  virtual std::string settings() const = 0;
};

}  // namespace fibremss
