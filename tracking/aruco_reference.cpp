#include "tracking/aruco_reference.h"

#include <opencv2/imgproc.hpp>
#ifdef NERFAR_HAVE_ARUCO
#include <opencv2/aruco.hpp>
#endif

namespace nerfar {

bool ArucoAvailable() {
#ifdef NERFAR_HAVE_ARUCO
  return true;
#else
  return false;
#endif
}

std::vector<TagDetection> DetectWithAruco(const Image8& image, ArucoRefine refine) {
  std::vector<TagDetection> out;
#ifdef NERFAR_HAVE_ARUCO
  if (image.empty() || (image.channels != 1 && image.channels != 3)) return out;
  cv::Mat view(image.height, image.width, CV_8UC(image.channels), const_cast<std::uint8_t*>(image.pixels.data()));
  cv::Mat gray;
  if (image.channels == 3) {
    cv::cvtColor(view, gray, cv::COLOR_RGB2GRAY);
  } else {
    gray = view;
  }
  static const cv::Ptr<cv::aruco::Dictionary> dictionary =
      cv::aruco::getPredefinedDictionary(cv::aruco::DICT_APRILTAG_36h11);
  cv::Ptr<cv::aruco::DetectorParameters> parameters = cv::aruco::DetectorParameters::create();
  parameters->cornerRefinementMethod = refine == ArucoRefine::kSubpix     ? cv::aruco::CORNER_REFINE_SUBPIX
                                       : refine == ArucoRefine::kAprilTag ? cv::aruco::CORNER_REFINE_APRILTAG
                                                                          : cv::aruco::CORNER_REFINE_NONE;
  std::vector<std::vector<cv::Point2f>> corners;
  std::vector<int> ids;
  try {
    cv::aruco::detectMarkers(gray, dictionary, corners, ids, parameters);
  } catch (const cv::Exception&) {
    return out;
  }
  for (size_t i = 0; i < ids.size(); ++i) {
    if (corners[i].size() != 4) continue;
    TagDetection d;
    d.id = ids[i];
    // aruco's corners are TL, TR, BR, BL of the marker as it draws it (the
    // board.json order); its pixel centres sit at integers, ours at +0.5.
    for (int c = 0; c < 4; ++c) d.corners[c] = {corners[i][c].x + 0.5, corners[i][c].y + 0.5};
    out.push_back(d);
  }
#else
  (void)image;
  (void)refine;
#endif
  return out;
}

}  // namespace nerfar
