#include "render/lighting/view_quality.h"

#include <cstdlib>
#include <filesystem>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/quality/qualitybrisque.hpp>

#include "calib/core/error.h"
#include "calib/core/image_io.h"

namespace nerfar {
namespace {
constexpr const char* kModelFile = "brisque_model_live.yml";
constexpr const char* kRangeFile = "brisque_range_live.yml";

bool HasModel(const std::string& dir) {
  namespace fs = std::filesystem;
  std::error_code ec;
  return !dir.empty() && fs::is_regular_file(fs::path(dir) / kModelFile, ec) &&
         fs::is_regular_file(fs::path(dir) / kRangeFile, ec);
}
}  // namespace

std::string FindBrisqueModelDir() {
  if (const char* env = std::getenv("NERFAR_BRISQUE_DIR"); env != nullptr && HasModel(env)) return env;
  for (const char* dir :
       {"/usr/share/opencv4/quality", "/usr/local/share/opencv4/quality", "/usr/share/opencv/quality"})
    if (HasModel(dir)) return dir;
  return "";
}

struct BrisqueScorer::Impl {
  cv::Ptr<cv::quality::QualityBRISQUE> model;
};

BrisqueScorer::BrisqueScorer(const std::string& model_dir) : impl_(std::make_unique<Impl>()) {
  if (!HasModel(model_dir))
    ThrowInputError(model_dir.empty() ? std::string("BRISQUE model") : model_dir,
                    std::string("no ") + kModelFile + " and " + kRangeFile +
                        " (expected the opencv-data package, or NERFAR_BRISQUE_DIR naming their folder)");
  try {
    impl_->model = cv::quality::QualityBRISQUE::create(model_dir + "/" + kModelFile, model_dir + "/" + kRangeFile);
  } catch (const cv::Exception& e) {
    ThrowInputError(model_dir, std::string("cannot load the BRISQUE model: ") + e.what());
  }
  if (impl_->model.empty()) ThrowInputError(model_dir, "cannot load the BRISQUE model");
}

BrisqueScorer::~BrisqueScorer() = default;

double BrisqueScorer::Score(const Image8& image) const {
  NERFAR_CHECK(image.channels == 1 || image.channels == 3);
  NERFAR_CHECK_GE(image.width, 16);
  NERFAR_CHECK_GE(image.height, 16);
  cv::Mat mat(image.height, image.width, image.channels == 1 ? CV_8UC1 : CV_8UC3,
              const_cast<uint8_t*>(image.pixels.data()));
  cv::Mat input;
  if (image.channels == 3)
    cv::cvtColor(mat, input, cv::COLOR_RGB2BGR);  // the module expects OpenCV's BGR order
  else
    input = mat;
  // The model works on floats in [0, 1] internally; hand it 8-bit data as OpenCV documents.
  const cv::Scalar score = impl_->model->compute(input);
  return score[0];
}

double BrisqueScorer::ScoreLinear(const ImageF& linear_rgb) const {
  return Score(ToneMapToDisplay(linear_rgb, ExposureForPercentile(linear_rgb)));
}

}  // namespace nerfar
