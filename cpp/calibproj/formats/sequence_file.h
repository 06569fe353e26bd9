#pragma once
// sequence.json (calibproj.sequence/1) read into the ingest's SequenceDescription and
// written from it. The one reader and writer of the format: calibproj-native and the
// Python package (Sequence.load, Sequence.save) accept and write exactly the same files.

#include <filesystem>
#include <nlohmann/json.hpp>

#include "calibproj/ingest/sequence_description.h"

namespace calibproj::formats {

// InputError naming the file for another kind of file, a newer schema, a missing or
// mistyped field or an inconsistent sequence.
ingest::SequenceDescription ReadSequence(const std::filesystem::path& path);

// The body of sequence.json (without its schema tag), in the file's order of keys.
nlohmann::ordered_json SequenceDocument(const ingest::SequenceDescription& sequence);

// sequence.json written atomically after sequence.Check(); InputError naming the file
// for a sequence whose parts disagree, with nothing written.
void WriteSequence(const std::filesystem::path& path, const ingest::SequenceDescription& sequence);

// The body of sequence.json (its schema tag not needed) checked field by field and for
// consistency (segments tile the frames, codes and patterns inside their segments,
// marker geometry of the family, centres of the layout's shape, ...);
// std::invalid_argument with the place and the problem ("at patterns/0: 'array' is a
// required property").
ingest::SequenceDescription SequenceFromDocument(const nlohmann::json& document);

}  // namespace calibproj::formats
