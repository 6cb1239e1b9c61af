#pragma once
// Lists in one line of text (internal to comparisons/src).
#include <string>

namespace fibremss {

/// Appends `item` to the "; "-separated list `list` (no separator before the first item).
inline void appendItem(std::string& list, const std::string& item) {
  list += (list.empty() ? "" : "; ") + item;
}

}  // namespace fibremss
