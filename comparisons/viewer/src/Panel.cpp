#include "Panel.h"

#include <imgui.h>

namespace fibremss::viewer {
namespace {

/// A button's width with `label` [px].
float buttonWidth(const char* label) {
  return ImGui::CalcTextSize(label).x + 2 * ImGui::GetStyle().FramePadding.x;
}

/// A button on the current line when it fits; returns whether it was pressed.
bool button(const char* label) {
  sameLineIfFits(buttonWidth(label));
  return ImGui::Button(label);
}

}  // namespace

void sameLineIfFits(float width) {
  const float right = ImGui::GetItemRectMax().x + ImGui::GetStyle().ItemSpacing.x + width;
  if (right <= ImGui::GetWindowPos().x + ImGui::GetWindowContentRegionMax().x) ImGui::SameLine();
}

float checkboxWidth(const char* label) {
  return ImGui::GetFrameHeight() + ImGui::GetStyle().ItemInnerSpacing.x +
         ImGui::CalcTextSize(label).x;
}

bool playbackButtons(Source& source, bool& loop) {
  // The keys are in the panel's help lines: the buttons stay short.
  if (ImGui::Button(source.playing() ? "Pause" : "Play")) source.togglePlaying();
  if (button("Step")) source.step();
  if (button("Reset")) source.reset();
  sameLineIfFits(checkboxWidth("loop"));
  return ImGui::Checkbox("loop", &loop);
}

void partTimes(const char* heading, const std::array<double, 5>& ms) {
  ImGui::TextUnformatted(heading);
  const char* parts[] = {"mss", "muscle CD", "bone CD", "response", "output"};
  for (size_t i = 0; i < ms.size(); ++i) ImGui::Text("  %s %.3g", parts[i], ms[i]);
}

}  // namespace fibremss::viewer
