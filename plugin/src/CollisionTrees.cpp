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

void SphereTree::build(std::span<const uint32_t> indices, std::span<const btVector3> centres,
                       std::span<const btScalar> radii, btScalar margin) {
  ++epoch_;
  tree_.clear();
  leaves_.clear();
  leaves_.reserve(indices.size());
  for (uint32_t index : indices) {
    btDbvtNode* leaf =
        tree_.insert(btDbvtVolume::FromCR(centres[index], radii[index] + margin), nullptr);
    leaf->dataAsInt = static_cast<int>(index);
    leaves_.push_back(leaf);
  }
  // Top-down optimisation gives a balanced tree to start from; it keeps the leaf nodes.
  if (!leaves_.empty()) tree_.optimizeTopDown();
  inner_.reserve(leaves_.size());
  pending_.reserve(leaves_.size());
  orderInnerNodes();
}

btScalar SphereTree::refit(std::span<const uint32_t> indices, std::span<const btVector3> centres,
                           std::span<const btScalar> radii, btScalar margin,
                           std::span<btVector3> snapshot) {
  ++epoch_;
  btScalar moved2 = 0;
  if (snapshot.empty()) {
    for (size_t k = 0; k < leaves_.size(); ++k)
      setSphereBounds(leaves_[k]->volume, centres[indices[k]], radii[indices[k]] + margin);
  } else {
    for (size_t k = 0; k < leaves_.size(); ++k) {
      const uint32_t i = indices[k];
      setSphereBounds(leaves_[k]->volume, centres[i], radii[i] + margin);
      moved2 = std::max(moved2, (centres[i] - snapshot[i]).length2());
      snapshot[i] = centres[i];
    }
  }
  for (btDbvtNode* node : inner_)
    mergeBounds(node->childs[0]->volume, node->childs[1]->volume, node->volume);
  return moved2;
}

void SphereTree::rebuild(std::span<const uint32_t> indices, std::span<const btVector3> centres,
                         std::span<const btScalar> radii, btScalar margin) {
  ++epoch_;
  for (size_t k = 0; k < leaves_.size(); ++k) {
    btDbvtVolume volume = btDbvtVolume::FromCR(centres[indices[k]], radii[indices[k]] + margin);
    tree_.update(leaves_[k], volume);  // remove and insert: reuses the freed node
  }
  orderInnerNodes();
}

void SphereTree::orderInnerNodes() {
  // Depth first from the root lists parents before children; reversed, children come first.
  inner_.clear();
  pending_.clear();
  if (tree_.m_root && tree_.m_root->isinternal()) pending_.push_back(tree_.m_root);
  while (!pending_.empty()) {
    btDbvtNode* node = pending_.back();
    pending_.pop_back();
    inner_.push_back(node);
    for (btDbvtNode* child : node->childs)
      if (child->isinternal()) pending_.push_back(child);
  }
  std::reverse(inner_.begin(), inner_.end());
}

void collideTrees(TreeTraversalStack& stack, const btDbvtNode* a, const btDbvtNode* b,
                  btDbvt::ICollide& policy) {
  // btDbvt::collideTTpersistentStack's traversal and pair order, but child pairs are tested
  // before they are pushed (most fail, and then cost no stack traffic). The stack grows like
  // Bullet grows it (never in practice: it holds a few entries per level of both trees).
  if (!a || !b || !boundsOverlap(a->volume, b->volume)) return;
  if (stack.size() < btDbvt::DOUBLE_STACKSIZE) stack.resize(btDbvt::DOUBLE_STACKSIZE);
  int depth = 0;
  // Written always, kept when they overlap: no branch on the test.
  const auto visit = [&](const btDbvtNode* x, const btDbvtNode* y) {
    stack[depth] = btDbvt::sStkNN(x, y);
    depth += boundsOverlap(x->volume, y->volume);
  };
  visit(a, b);
  while (depth > 0) {
    const btDbvt::sStkNN pair = stack[--depth];
    if (depth + 4 > stack.size()) stack.resize(stack.size() * 2);
    if (pair.a->isinternal()) {
      if (pair.b->isinternal()) {
        visit(pair.a->childs[0], pair.b->childs[0]);
        visit(pair.a->childs[1], pair.b->childs[0]);
        visit(pair.a->childs[0], pair.b->childs[1]);
        visit(pair.a->childs[1], pair.b->childs[1]);
      } else {
        visit(pair.a->childs[0], pair.b);
        visit(pair.a->childs[1], pair.b);
      }
    } else if (pair.b->isinternal()) {
      visit(pair.a, pair.b->childs[0]);
      visit(pair.a, pair.b->childs[1]);
    } else {
      policy.Process(pair.a, pair.b);
    }
  }
}

void BoneSphereTree::build(std::span<const btVector3> centres, std::span<const btScalar> radii) {
  nodes_.clear();
  bounds_.clear();
  centres_.clear();
  if (centres.empty()) return;
  btDbvt tree;
  for (size_t k = 0; k < centres.size(); ++k)
    tree.insert(btDbvtVolume::FromCR(centres[k], radii[k]), nullptr)->dataAsInt =
        static_cast<int>(k);
  tree.optimizeTopDown();
  // Flatten depth first; a parent's index is below its children's.
  std::vector<std::pair<const btDbvtNode*, int32_t>> pending{{tree.m_root, 0}};
  nodes_.emplace_back();
  while (!pending.empty()) {
    const auto [node, index] = pending.back();
    pending.pop_back();
    if (node->isleaf()) {
      nodes_[index].sphere = node->dataAsInt;
      continue;
    }
    for (int c = 0; c < 2; ++c) {
      const auto child = static_cast<int32_t>(nodes_.size());
      nodes_[index].children[c] = child;
      nodes_.emplace_back();
      pending.emplace_back(node->childs[c], child);
    }
  }
  bounds_.resize(nodes_.size());
  centres_.resize(centres.size());
  place(btTransform::getIdentity(), centres, radii);
}

void BoneSphereTree::place(const btTransform& boneToWorld, std::span<const btVector3> centres,
                           std::span<const btScalar> radii) {
  ++placement_;
  for (size_t k = 0; k < centres.size(); ++k) centres_[k] = boneToWorld * centres[k];
  for (size_t n = nodes_.size(); n-- > 0;) {
    const Node& node = nodes_[n];
    if (node.sphere >= 0)
      setSphereBounds(bounds_[n], centres_[node.sphere], radii[node.sphere]);
    else
      mergeBounds(bounds_[node.children[0]], bounds_[node.children[1]], bounds_[n]);
  }
}

}  // namespace fibremss
