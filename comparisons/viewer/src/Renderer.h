#pragma once
// Draws a ViewFrame and what a DebugDrawer collected with OpenGL 2.1 (vertex arrays and the
// fixed-function pipeline: no function loader needed, runs on any Mesa driver including
// llvmpipe under Xvfb): bones ivory, muscle surfaces coloured by an array, lit by a
// headlight; debug lines and points on top of the bones, inside translucent muscles.
#include <string>
#include <vector>

#include "Colours.h"
#include "DebugDrawer.h"
#include "ViewFrame.h"
#include "fibremss/viewer/Camera.h"

namespace fibremss::viewer {

/// The part of the window the scene is drawn in [px, from the bottom left].
struct Viewport {
  int x = 0;       ///< left edge
  int y = 0;       ///< bottom edge
  int width = 0;   ///< width
  int height = 0;  ///< height
};

/// What to draw and how.
struct RenderSettings {
  bool bones = true;                    ///< draw the bone meshes
  bool surfaces = true;                 ///< draw the muscle surfaces
  float surfaceOpacity = 1;             ///< muscle surfaces' opacity (0..1; < 1 shows the inside)
  std::string colourBy = "muscle_id";   ///< the array muscles are coloured by
  Range range;                          ///< the values at the colour map's ends
  float pointSize = 3;                  ///< debug points (particles, bone spheres) [px]
  Rgb background{0.16f, 0.17f, 0.20f};  ///< clear colour
  Rgb boneColour{0.86f, 0.84f, 0.76f};  ///< bones' colour
  Rgb toolColour{0.35f, 0.75f, 0.35f};  ///< the pointer's tools' colour (green)
};

class Renderer {
 public:
  /// Clears the whole window and draws into `viewport`.
  void draw(const ViewFrame& frame, const DebugGeometry& debug, const Camera& camera,
            const Viewport& viewport, const RenderSettings& settings);

 private:
  /// Fills xyz_ and normals_ (area-weighted vertex normals) from `mesh`.
  void prepareGeometry(const ViewMesh& mesh);
  void drawMesh(const ViewMesh& mesh, bool perVertexColour);
  void drawDebug(const DebugGeometry& debug, float pointSize);

  std::vector<float> xyz_;      ///< vertex positions (scratch)
  std::vector<float> normals_;  ///< vertex normals (scratch)
  std::vector<float> colours_;  ///< rgba per vertex (scratch)
};

}  // namespace fibremss::viewer
