// The registry of mesh file formats: which reader a file goes to, and the lists of accepted
// formats the loaders' messages give.
#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <utility>

#include "MeshIOInternal.h"
#include "fibremss/Error.h"

namespace fibremss::meshio {
namespace {

/// The registered formats, made on first use (registrations run as the library loads, in any
/// order), kept in the order of their first extension, the fallback last.
std::vector<MeshFormat>& registered() {
  static std::vector<MeshFormat> formats;
  return formats;
}

/// The first extension naming a format ("~" after every extension for the fallback).
std::string sortKey(const MeshFormat& format) {
  return format.extensions.empty() ? "~" : format.extensions.front();
}

bool reads(const MeshFormat& format, MeshUse use) {
  return use == MeshUse::Surface ? format.readSurface != nullptr : format.readFibres != nullptr;
}

bool named(const MeshFormat& format, const std::string& extension) {
  return std::ranges::find(format.extensions, extension) != format.extensions.end();
}

/// Stops the program when `format` claims what a registered format already does.
void requireUnclaimed(const MeshFormat& format) {
  for (const MeshFormat& other : registered()) {
    const bool clash = (format.fallback && other.fallback) ||
                       std::ranges::any_of(format.extensions, [&](const std::string& extension) {
                         return named(other, extension);
                       });
    if (clash) {
      std::fprintf(stderr, "fibremss: mesh formats %s and %s claim the same files\n", other.name,
                   format.name);
      std::abort();
    }
  }
}

/// The file's first kSignatureBytes bytes; InputError when it cannot be opened.
std::string fileHead(const std::string& path) {
  std::ifstream file(path, std::ios::binary);
  if (!file) throw InputError(path, "", std::string("cannot open: ") + std::strerror(errno));
  std::string head(kSignatureBytes, '\0');
  file.read(head.data(), static_cast<std::streamsize>(head.size()));
  head.resize(static_cast<size_t>(file.gcount()));
  return head;
}

/// `items` joined by ", ", the last by `last`.
std::string joined(const std::vector<std::string>& items, const std::string& last) {
  std::string text;
  for (size_t i = 0; i < items.size(); ++i) {
    if (i > 0) text += i + 1 == items.size() ? last : ", ";
    text += items[i];
  }
  return text;
}

}  // namespace

MeshFormatRegistration::MeshFormatRegistration(MeshFormat format) {
  requireUnclaimed(format);
  std::vector<MeshFormat>& formats = registered();
  const auto at = std::ranges::upper_bound(formats, sortKey(format), {}, sortKey);
  formats.insert(at, std::move(format));
}

std::string lowerExtension(const std::string& path) {
  std::string extension = std::filesystem::path(path).extension().string();
  for (char& c : extension) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return extension;
}

const MeshFormat* meshFormatFor(const std::string& path, MeshUse use) {
  const std::string extension = lowerExtension(path);
  const auto first = [&](auto&& test) -> const MeshFormat* {
    for (const MeshFormat& format : registered())
      if (reads(format, use) && test(format)) return &format;
    return nullptr;
  };
  if (const MeshFormat* format =
          first([&](const MeshFormat& f) { return f.recognises && named(f, extension); }))
    return format;
  const std::string head = fileHead(path);
  if (const MeshFormat* format =
          first([&](const MeshFormat& f) { return f.recognises && f.recognises(head); }))
    return format;
  if (const MeshFormat* format = first([&](const MeshFormat& f) { return named(f, extension); }))
    return format;
  return first([](const MeshFormat& f) { return f.fallback; });
}

std::string fibreFormatList() {
  std::vector<std::string> items;
  for (const MeshFormat& format : registered()) {
    if (!reads(format, MeshUse::Fibres)) continue;
    std::string item = std::string(format.name) + " (";
    for (const std::string& extension : format.extensions) item += extension + ", ";
    items.push_back(item + format.fibreElements + ")");
  }
  return joined(items, " or ");
}

std::string surfaceFormatList() {
  std::vector<std::string> items;
  for (const MeshFormat& format : registered())
    if (reads(format, MeshUse::Surface)) items.push_back(format.name);
  return joined(items, ", ");
}

}  // namespace fibremss::meshio
