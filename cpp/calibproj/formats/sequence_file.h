#pragma once
// sequence.json (calibproj.sequence/1) read into the ingest's SequenceDescription, with
// the same fields the Python binding takes from Sequence.to_dict().

#include <filesystem>

#include "calibproj/ingest/sequence_description.h"

namespace calibproj::formats {

// InputError naming the file for another kind of file, a newer schema, a missing or
// mistyped field or an inconsistent sequence.
ingest::SequenceDescription ReadSequence(const std::filesystem::path& path);

}  // namespace calibproj::formats
