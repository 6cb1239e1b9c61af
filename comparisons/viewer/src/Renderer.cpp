#include "Renderer.h"

#include <GL/gl.h>

#include <algorithm>
#include <array>
#include <cmath>

namespace fibremss::viewer {
namespace {

std::array<float, 16> toGl(const btTransform& transform) {
  btScalar m[16];
  transform.getOpenGLMatrix(m);
  std::array<float, 16> f;
  std::transform(m, m + 16, f.begin(), [](btScalar v) { return static_cast<float>(v); });
  return f;
}

/// A headlight: white light from the eye, with some ambient light.
void setLights() {
  glMatrixMode(GL_MODELVIEW);
  glLoadIdentity();
  const GLfloat position[] = {0, 0.3f, 1, 0}, diffuse[] = {0.75f, 0.75f, 0.75f, 1},
                ambient[] = {0.3f, 0.3f, 0.3f, 1}, specular[] = {0.15f, 0.15f, 0.15f, 1};
  glLightfv(GL_LIGHT0, GL_POSITION, position);
  glLightfv(GL_LIGHT0, GL_DIFFUSE, diffuse);
  glLightfv(GL_LIGHT0, GL_AMBIENT, ambient);
  glLightfv(GL_LIGHT0, GL_SPECULAR, specular);
  glLightModeli(GL_LIGHT_MODEL_TWO_SIDE, GL_TRUE);
  glEnable(GL_LIGHT0);
  glEnable(GL_COLOR_MATERIAL);
  glColorMaterial(GL_FRONT_AND_BACK, GL_AMBIENT_AND_DIFFUSE);
  glEnable(GL_NORMALIZE);
}

}  // namespace

void Renderer::draw(const ViewFrame& frame, const DebugGeometry& debug, const Camera& camera,
                    const Viewport& viewport, const RenderSettings& settings) {
  glClearColor(settings.background[0], settings.background[1], settings.background[2], 1);
  glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
  glViewport(viewport.x, viewport.y, viewport.width, viewport.height);
  glEnable(GL_DEPTH_TEST);
  glDisable(GL_CULL_FACE);
  glDisable(GL_BLEND);
  glDepthMask(GL_TRUE);
  glMatrixMode(GL_PROJECTION);
  glLoadMatrixf(
      camera.projection(float(viewport.width) / float(std::max(viewport.height, 1))).data());
  setLights();
  glLoadMatrixf(camera.view().data());

  glEnable(GL_LIGHTING);
  if (settings.bones) {
    glColor3f(settings.boneColour[0], settings.boneColour[1], settings.boneColour[2]);
    for (const ViewMesh& bone : frame.bones) drawMesh(bone, false);
  }
  glColor3f(settings.toolColour[0], settings.toolColour[1], settings.toolColour[2]);
  for (const ViewMesh& tool : frame.tools) drawMesh(tool, false);
  glDisable(GL_LIGHTING);
  drawDebug(debug, settings.pointSize);

  if (!settings.surfaces || settings.surfaceOpacity <= 0) return;
  glEnable(GL_LIGHTING);
  if (settings.surfaceOpacity < 1) {
    glEnable(GL_BLEND);
    glBlendFunc(GL_SRC_ALPHA, GL_ONE_MINUS_SRC_ALPHA);
    glDepthMask(GL_FALSE);
  }
  for (const ViewMesh& muscle : frame.muscles) {
    const std::vector<float>* values = muscle.array(settings.colourBy);
    colours_.resize(4 * muscle.vertices.size());
    for (size_t v = 0; v < muscle.vertices.size(); ++v) {
      const Rgb c = values && v < values->size()
                        ? colourOf(settings.colourBy, (*values)[v], settings.range)
                        : Rgb{0.6f, 0.6f, 0.6f};
      std::copy(c.begin(), c.end(), colours_.begin() + 4 * v);
      colours_[4 * v + 3] = settings.surfaceOpacity;
    }
    drawMesh(muscle, true);
  }
  glDepthMask(GL_TRUE);
  glDisable(GL_BLEND);
  glDisable(GL_LIGHTING);
}

void Renderer::prepareGeometry(const ViewMesh& mesh) {
  const size_t n = mesh.vertices.size();
  xyz_.resize(3 * n);
  for (size_t v = 0; v < n; ++v)
    for (int k = 0; k < 3; ++k) xyz_[3 * v + k] = static_cast<float>(mesh.vertices[v][k]);
  normals_.assign(3 * n, 0.0f);
  for (const auto& t : *mesh.triangles) {
    const btVector3 normal = (mesh.vertices[t[1]] - mesh.vertices[t[0]])
                                 .cross(mesh.vertices[t[2]] - mesh.vertices[t[0]]);
    for (uint32_t v : t)
      for (int k = 0; k < 3; ++k) normals_[3 * v + k] += static_cast<float>(normal[k]);
  }
}

void Renderer::drawMesh(const ViewMesh& mesh, bool perVertexColour) {
  if (!mesh.triangles || mesh.triangles->empty()) return;
  prepareGeometry(mesh);
  glPushMatrix();
  glMultMatrixf(toGl(mesh.transform).data());
  glEnableClientState(GL_VERTEX_ARRAY);
  glEnableClientState(GL_NORMAL_ARRAY);
  glVertexPointer(3, GL_FLOAT, 0, xyz_.data());
  glNormalPointer(GL_FLOAT, 0, normals_.data());
  if (perVertexColour) {
    glEnableClientState(GL_COLOR_ARRAY);
    glColorPointer(4, GL_FLOAT, 0, colours_.data());
  }
  glDrawElements(GL_TRIANGLES, static_cast<GLsizei>(3 * mesh.triangles->size()), GL_UNSIGNED_INT,
                 mesh.triangles->data());
  glDisableClientState(GL_COLOR_ARRAY);
  glDisableClientState(GL_NORMAL_ARRAY);
  glDisableClientState(GL_VERTEX_ARRAY);
  glPopMatrix();
}

void Renderer::drawDebug(const DebugGeometry& debug, float pointSize) {
  glEnableClientState(GL_VERTEX_ARRAY);
  glEnableClientState(GL_COLOR_ARRAY);
  if (!debug.lineVertices.empty()) {
    glVertexPointer(3, GL_FLOAT, 0, debug.lineVertices.data());
    glColorPointer(3, GL_FLOAT, 0, debug.lineColours.data());
    glDrawArrays(GL_LINES, 0, static_cast<GLsizei>(debug.lineVertices.size() / 3));
  }
  if (!debug.points.empty()) {
    glPointSize(pointSize);
    glVertexPointer(3, GL_FLOAT, 0, debug.points.data());
    glColorPointer(3, GL_FLOAT, 0, debug.pointColours.data());
    glDrawArrays(GL_POINTS, 0, static_cast<GLsizei>(debug.points.size() / 3));
  }
  glDisableClientState(GL_COLOR_ARRAY);
  glDisableClientState(GL_VERTEX_ARRAY);
}

}  // namespace fibremss::viewer
