#include "synthetic/generate_database_command.h"

#include <cstdlib>
#include <iomanip>
#include <iostream>

#include <boost/program_options.hpp>

#include "synthetic/database_generator.h"

namespace po = boost::program_options;

namespace cashash {
namespace colmap {

int RunGenerateDatabase(int argc, const char* const* argv) {
  DatabaseGeneratorOptions o;
  po::options_description description("cashash generate_database options");
  // Defaults are shown from the struct, so help and behaviour cannot drift.
  description.add_options()("help,h", "Print this help")(
      "database_path", po::value(&o.database_path), "New COLMAP database to write (must not exist)")(
      "source_database_path", po::value(&o.source_database_path),
      "COLMAP database with SIFT features whose descriptors are sampled (only read)")(
      "num_images", po::value(&o.num_images), "Images (cameras along a street)")(
      "revisit_images", po::value(&o.revisit_images)->default_value(o.revisit_images),
      "The last this many images drive the start of the street again (each near the pose of image k - "
      "(num_images - revisit_images), seeing the same points), so that sequential matching has loops to close; "
      "0 = a street that never comes back")(
      "num_features", po::value(&o.num_features)->default_value(o.num_features),
      "Features per image: exactly (equal), or the extractor's cap (extraction)")(
      "num_features_distribution", po::value(&o.num_features_distribution)->default_value(o.num_features_distribution),
      "equal: every image has num_features. extraction: like COLMAP's SIFT extraction, where textured images "
      "fill the cap and plain, blurred or small ones fall below it: a share num_features_at_cap_share of the "
      "images has num_features, the others a count drawn evenly from [min_num_features, num_features)")(
      "min_num_features", po::value(&o.min_num_features)->default_value(o.min_num_features),
      "extraction: fewest features of an image; 0 = num_features / 8")(
      "num_features_at_cap_share", po::value(&o.num_features_at_cap_share)->default_value(o.num_features_at_cap_share),
      "extraction: share of the images at num_features")(
      "num_points", po::value(&o.num_points)->default_value(o.num_points),
      "3D points of the scene; 0 = enough for each image to see num_features x (1 - distractor_ratio)")(
      "random_seed", po::value(&o.random_seed)->default_value(o.random_seed), "Seed: same seed, same database")(
      "image_width", po::value(&o.image_width)->default_value(o.image_width), "Image width in pixels")(
      "image_height", po::value(&o.image_height)->default_value(o.image_height), "Image height in pixels")(
      "camera_model", po::value(&o.camera_model)->default_value(o.camera_model),
      "SIMPLE_RADIAL, PINHOLE or SIMPLE_PINHOLE; one camera per image, focal prior known")(
      "focal_length_factor", po::value(&o.focal_length_factor)->default_value(o.focal_length_factor),
      "Focal length in units of max(width, height)")(
      "distractor_ratio", po::value(&o.distractor_ratio)->default_value(o.distractor_ratio),
      "Share of features at random places with random descriptors")(
      "keypoint_noise", po::value(&o.keypoint_noise)->default_value(o.keypoint_noise),
      "Keypoint position noise, pixels (standard deviation)")(
      "descriptor_noise", po::value(&o.descriptor_noise)->default_value(o.descriptor_noise),
      "Descriptor noise per value, stored uint8 units (standard deviation)")(
      "images_per_transaction", po::value(&o.images_per_transaction)->default_value(o.images_per_transaction),
      "Images written per database transaction")(
      "num_threads", po::value(&o.num_threads)->default_value(o.num_threads),
      "Threads making images (-1 = all cores); any count writes the same database")(
      "source_max_images", po::value(&o.source_max_images)->default_value(o.source_max_images),
      "Source images whose descriptors are used (their repeated views of a point are kept once)")(
      "position_priors", po::value(&o.position_priors)->default_value(o.position_priors),
      "Position priors of the images (for spatial_matcher): none, cartesian (true centres, street units as "
      "metres) or gps (the same as WGS84 latitude, longitude, altitude)")(
      "ground_truth_path", po::value(&o.ground_truth_path),
      "Folder for the true cameras as a COLMAP text model (optional)");
  po::variables_map vm;
  try {
    po::store(po::command_line_parser(argc, argv).options(description).run(), vm);
    po::notify(vm);
  } catch (const po::error& e) {
    std::cerr << "ERROR: " << e.what() << " (see cashash generate_database --help)" << std::endl;
    return EXIT_FAILURE;
  }
  if (vm.count("help")) {
    std::cout << description << std::endl;
    return EXIT_SUCCESS;
  }
  try {
    std::cout << std::fixed;
    const GeneratorSummary summary = GenerateDatabase(o, [](const GeneratorProgress& p) {
      const double rate = p.elapsed_seconds > 0 ? p.images_done / p.elapsed_seconds : 0.0;
      std::cout << "Generated " << p.images_done << "/" << p.images_total << " images (" << std::setprecision(1)
                << 100.0 * p.images_done / p.images_total << "%, " << rate << " images/s)" << std::endl;
    });
    const double mib = summary.file_bytes / (1024.0 * 1024.0);
    std::cout << "Source: " << summary.pool_descriptors << " distinct descriptors of " << summary.source_descriptors
              << " in " << summary.source_images << " images" << std::endl;
    std::cout << "Scene: " << summary.num_scene_points << " 3D points; "
              << std::setprecision(1)
              << 100.0 * summary.observed_features / std::max<int64_t>(1, summary.num_features)
              << "% of the features are 3D points, " << summary.images_short_of_points
              << " images saw fewer points than planned; keypoints with " << summary.keypoint_columns
              << " columns" << std::endl;
    std::cout << "Wrote " << summary.num_images << " images x ";
    if (summary.min_features == summary.max_features) {
      std::cout << summary.max_features << " features";
    } else {
      std::cout << summary.min_features << "-" << summary.max_features << " features (mean " << std::setprecision(0)
                << static_cast<double>(summary.num_features) / std::max(1, summary.num_images) << ")";
    }
    std::cout << " to " << o.database_path << ": " << std::setprecision(1) << mib << " MiB in " << std::setprecision(2)
              << summary.seconds << " s" << std::endl;
  } catch (const std::exception& e) {
    std::cerr << "ERROR: " << e.what() << std::endl;
    return EXIT_FAILURE;
  }
  return EXIT_SUCCESS;
}

}  // namespace colmap
}  // namespace cashash
