// Inputs are never written. Before a command does any work it names every
// file it will write and every file it reads; CheckOutputsSpareInputs refuses
// (InputError, exit 2, naming both paths) when an output is an input.
// "The same file" means the same path once both are made absolute with
// symbolic links, "." and ".." resolved (for files that do not exist yet,
// the existing part of the path), or the same file through a hard link.
// An input that is a folder (an image-folder source) stands for the files
// directly in it. Empty paths are ignored in both lists.
#pragma once

#include <string>
#include <vector>

namespace nerfar {

// The paths of `names` inside `folder`: the files a command writes there.
std::vector<std::string> FilesIn(const std::string& folder, const std::vector<std::string>& names);

// InputError "OUTPUT: would overwrite the input INPUT ..." for the first
// output that is the same file as an input, or that is given twice (two
// outputs of one command, e.g. -o and --preview, in one file).
void CheckOutputsSpareInputs(const std::vector<std::string>& outputs, const std::vector<std::string>& inputs);

}  // namespace nerfar
