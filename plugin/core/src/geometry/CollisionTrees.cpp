#include "CollisionTrees.h"

#include <algorithm>

namespace fibremss {
namespace {

/// btDbvtVolume::FromCR(centre, radius), written in place: the same values.
void setSphereBounds(btDbvtVolume& bounds, const btVector3& centre, btScalar radius) {
#if FIBREMSS_SSE_BOUNDS
  const __m128 c = _mm_load_ps(centre.m_floats), r = _mm_setr_ps(radius, radius, radius, 0);
  _mm_store_ps(bounds.tMins().m_floats, _mm_sub_ps(c, r));
  _mm_store_ps(bounds.tMaxs().m_floats, _mm_add_ps(c, r));
#else
  bounds = btDbvtVolume::FromCR(centre, radius);
#endif
}

/// Bullet's Merge(a, b, r) without its branch per coordinate (unpredictable in a refit): the
/// lane-wise minimum and maximum, the same values.
void mergeBounds(const btDbvtVolume& a, const btDbvtVolume& b, btDbvtVolume& r) {
#if FIBREMSS_SSE_BOUNDS
  _mm_store_ps(r.tMins().m_floats,
               _mm_min_ps(_mm_load_ps(a.Mins().m_floats), _mm_load_ps(b.Mins().m_floats)));
  _mm_store_ps(r.tMaxs().m_floats,
               _mm_max_ps(_mm_load_ps(a.Maxs().m_floats), _mm_load_ps(b.Maxs().m_floats)));
#else
  Merge(a, b, r);
#endif
}

}  // namespace

template <typename BoundsOf>
void FlatSphereTree::buildDbvt(btDbvt& tree, size_t count, BoundsOf&& boundsOf) {
  tree.clear();
  for (size_t k = 0; k < count; ++k)
    tree.insert(boundsOf(k), nullptr)->dataAsInt = static_cast<int>(k);
  if (count > 0) tree.optimizeTopDown();
}

void FlatSphereTree::flatten(btDbvt& tree, size_t leafCount, std::vector<btDbvtNode*>& sources) {
  const size_t count = leafCount ? 2 * leafCount - 1 : 0;
  nodes_.assign(count, Node{});
  bounds_.resize(count);
  sources.resize(count);
  firstLeaf_ = leafCount ? static_cast<int32_t>(leafCount - 1) : 0;
  if (!tree.m_root) return;
  // Depth first; an inner node numbers its children when it is reached, so they follow it.
  int32_t nextInner = 0;
  const auto number = [&](const btDbvtNode* node) {
    return node->isleaf() ? firstLeaf_ + node->dataAsInt : nextInner++;
  };
  pending_.clear();
  pending_.reserve(leafCount + 1);  // the deepest a rebuilt tree can get: no allocation then
  pending_.emplace_back(tree.m_root, number(tree.m_root));
  while (!pending_.empty()) {
    const auto [node, index] = pending_.back();
    pending_.pop_back();
    sources[index] = node;
    bounds_[index] = node->volume;
    if (node->isleaf()) {
      nodes_[index].sphere = node->dataAsInt;
      continue;
    }
    for (int c = 0; c < 2; ++c) {
      const int32_t child = number(node->childs[c]);
      nodes_[index].children[c] = child;
      pending_.emplace_back(node->childs[c], child);
    }
  }
}

void FlatSphereTree::mergeInner() {
  for (int32_t n = firstLeaf_; n-- > 0;)
    mergeBounds(bounds_[nodes_[n].children[0]], bounds_[nodes_[n].children[1]], bounds_[n]);
}

void SphereTree::build(std::span<const uint32_t> indices, std::span<const btVector3> centres,
                       std::span<const btScalar> radii, btScalar margin, bool rebuildable) {
  ++epoch_;
  spheres_.assign(indices.begin(), indices.end());
  buildTopology(centres, radii, margin);
  copyTree();
  if (!rebuildable) {
    tree_.clear();
    std::vector<btDbvtNode*>().swap(dbvtNodes_);
  }
}

void SphereTree::buildTopology(std::span<const btVector3> centres, std::span<const btScalar> radii,
                               btScalar margin) {
  buildDbvt(tree_, spheres_.size(), [&](size_t k) {
    return btDbvtVolume::FromCR(centres[spheres_[k]], radii[spheres_[k]] + margin);
  });
}

btScalar SphereTree::refit(std::span<const btVector3> centres, std::span<const btScalar> radii,
                           btScalar margin, std::span<btVector3> snapshot) {
  ++epoch_;
  btScalar moved2 = 0;
  btDbvtVolume* leaves = bounds_.data() + firstLeaf_;
  if (snapshot.empty()) {
    for (size_t k = 0; k < spheres_.size(); ++k)
      setSphereBounds(leaves[k], centres[spheres_[k]], radii[spheres_[k]] + margin);
  } else {
    for (size_t k = 0; k < spheres_.size(); ++k) {
      const uint32_t i = spheres_[k];
      setSphereBounds(leaves[k], centres[i], radii[i] + margin);
      moved2 = std::max(moved2, (centres[i] - snapshot[i]).length2());
      snapshot[i] = centres[i];
    }
  }
  mergeInner();
  return moved2;
}

void SphereTree::rebuild(std::span<const btVector3> centres, std::span<const btScalar> radii,
                         btScalar margin) {
  ++epoch_;
  if (!tree_.m_root) {
    buildTopology(centres, radii, margin);  // built not rebuildable
  } else {
    // The btDbvt's bounds as the last refit left them guide the re-insertions.
    for (size_t n = 0; n < nodes_.size(); ++n) dbvtNodes_[n]->volume = bounds_[n];
    for (size_t k = 0; k < spheres_.size(); ++k) {
      btDbvtVolume volume = btDbvtVolume::FromCR(centres[spheres_[k]], radii[spheres_[k]] + margin);
      tree_.update(dbvtNodes_[leaf(k)], volume);  // remove and insert: reuses the freed node
    }
  }
  copyTree();
}

void SphereTree::copyTree() {
  flatten(tree_, spheres_.size(), dbvtNodes_);
  for (size_t k = 0; k < spheres_.size(); ++k)
    nodes_[leaf(k)].sphere = static_cast<int32_t>(spheres_[k]);
}

void BoneSphereTree::build(std::span<const btVector3> centres, std::span<const btScalar> radii) {
  btDbvt tree;
  buildDbvt(tree, centres.size(),
            [&](size_t k) { return btDbvtVolume::FromCR(centres[k], radii[k]); });
  std::vector<btDbvtNode*> sources;
  flatten(tree, centres.size(), sources);
  centres_.resize(centres.size());
  place(btTransform::getIdentity(), centres, radii);
}

void BoneSphereTree::place(const btTransform& boneToWorld, std::span<const btVector3> centres,
                           std::span<const btScalar> radii) {
  ++placement_;
  for (size_t k = 0; k < centres.size(); ++k) {
    centres_[k] = boneToWorld * centres[k];
    setSphereBounds(bounds_[leaf(k)], centres_[k], radii[k]);
  }
  mergeInner();
}

}  // namespace fibremss
