#pragma once
// sequence.json (calibproj.sequence/1) read into the ingest's SequenceDescription. The
// one reader of the format: calibproj-native, the ingest binding (Sequence.to_dict())
// and the Python package's Sequence.load all accept exactly the documents it accepts.

#include <filesystem>
#include <nlohmann/json.hpp>

#include "calibproj/ingest/sequence_description.h"

namespace calibproj::formats {

// InputError naming the file for another kind of file, a newer schema, a missing or
// mistyped field or an inconsistent sequence.
ingest::SequenceDescription ReadSequence(const std::filesystem::path& path);

// The file's document with what ReadSequence makes of it (the Python package builds
// its Sequence from the document once the core accepted it).
struct SequenceFile {
  nlohmann::json document;
  ingest::SequenceDescription description;
};
SequenceFile ReadSequenceFile(const std::filesystem::path& path);

// The body of sequence.json (its schema tag not needed) checked field by field and for
// consistency (segments tile the frames, codes and patterns inside their segments,
// marker geometry of the family, centres of the layout's shape, ...);
// std::invalid_argument with the place and the problem ("at patterns/0: 'array' is a
// required property").
ingest::SequenceDescription SequenceFromDocument(const nlohmann::json& document);

}  // namespace calibproj::formats
