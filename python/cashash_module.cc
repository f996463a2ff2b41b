// cashash._core: the C++ calls behind the Python package (cashash/__init__.py
// adds keyword options and numpy conversions on top).
#include <pybind11/functional.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <atomic>
#include <cstring>
#include <exception>
#include <optional>
#include <stdexcept>

#include "cashash/geometry/camera_models.h"
#include "cashash/matching/pair_matching.h"
#include "cashash/matching/table_shape.h"
#include "colmap_bridge/api/build_info.h"
#include "colmap_bridge/api/run_devices.h"
#include "colmap_bridge/api/matching_api.h"
#include "colmap_bridge/api/retrieval_api.h"

namespace py = pybind11;

namespace cashash {
namespace {

using colmap::MatcherCommandOptions;
using U8Array = py::array_t<uint8_t, py::array::c_style | py::array::forcecast>;
using F32Array = py::array_t<float, py::array::c_style | py::array::forcecast>;

FeatureDescriptors ToDescriptors(const U8Array& array, const char* name) {
  if (array.ndim() != 2 || array.shape(1) != kDescriptorDim) {
    throw std::invalid_argument(std::string(name) + ": expected an N x 128 array of SIFT descriptors");
  }
  FeatureDescriptors descriptors;
  descriptors.data.assign(array.data(), array.data() + array.size());
  return descriptors;
}

// Rows of x, y (further columns, e.g. COLMAP's affine shape, are ignored:
// verification needs positions only).
Keypoints ToKeypoints(const std::optional<F32Array>& array, const char* name) {
  Keypoints keypoints;
  if (!array) return keypoints;
  if (array->ndim() != 2 || array->shape(1) < 2) {
    throw std::invalid_argument(std::string(name) + ": expected an N x 2 (or wider) array of keypoint positions");
  }
  const auto view = array->unchecked<2>();
  keypoints.resize(static_cast<size_t>(view.shape(0)));
  for (py::ssize_t i = 0; i < view.shape(0); ++i) {
    keypoints[i].x = view(i, 0);
    keypoints[i].y = view(i, 1);
  }
  return keypoints;
}

py::array_t<uint32_t> MatchesToArray(const FeatureMatches& matches) {
  py::array_t<uint32_t> array({static_cast<py::ssize_t>(matches.size()), py::ssize_t{2}});
  auto view = array.mutable_unchecked<2>();
  for (size_t i = 0; i < matches.size(); ++i) {
    view(i, 0) = matches[i].point2D_idx1;
    view(i, 1) = matches[i].point2D_idx2;
  }
  return array;
}

template <typename Matrix>
py::array_t<double> EigenToArray(const Matrix& m) {
  py::array_t<double> array(m.cols() == 1 ? std::vector<py::ssize_t>{m.rows()}
                                          : std::vector<py::ssize_t>{m.rows(), m.cols()});
  auto* out = array.mutable_data();
  for (Eigen::Index r = 0; r < m.rows(); ++r) {
    for (Eigen::Index c = 0; c < m.cols(); ++c) out[r * m.cols() + c] = m(r, c);
  }
  return array;
}

py::dict RunToDict(const colmap::ResolvedRun& resolved) {
  py::dict run;
  run["matcher"] = MatcherTypeToString(resolved.options.cashash.matcher);
  run["num_tables"] = resolved.options.cashash.num_tables;
  run["bits_per_table"] = resolved.options.cashash.bits_per_table;
  run["tau"] = resolved.options.cashash.tau;
  run["exact_rematch_min_matches"] = resolved.options.cashash.exact_rematch_min_matches;
  run["exact_rematch_max_matches"] = resolved.options.cashash.exact_rematch_max_matches;
  run["rematch_on_matching_thread"] = resolved.rematch.where == RematchPlace::kMatchingThread;
  run["exact_rematch_where"] = RematchPlaceName(resolved.rematch.where);
  run["block_size"] = resolved.options.block_size;
  run["blocks_per_group"] = resolved.schedule.blocks_per_group;
  run["gpu_index"] = resolved.gpu_index;
  run["gpu_memory_budget_bytes"] = resolved.gpu_memory_budget_bytes;
  run["max_host_bytes"] = resolved.max_host_bytes;
  return run;
}

py::dict SummaryToDict(const colmap::MatchingSummary& s) {
  py::dict d;
  d["pairs_requested"] = s.pairs_requested;
  d["pairs_skipped"] = s.pairs_skipped;
  d["pairs_done"] = s.pipeline.pairs_done;
  d["matcher"] = s.matcher_name;
  d["raw_matches"] = s.pipeline.raw_matches;
  d["verified_pairs"] = s.pipeline.verified_pairs;
  d["inlier_matches"] = s.pipeline.inlier_matches;
  d["seconds"] = s.pipeline.seconds_total;
  d["stopped"] = s.pipeline.stopped;
  // The run's owner of GPU memory: at most this much held (0 without a GPU),
  // and how often a GPU part went on on the CPU for want of device memory.
  d["gpu_memory_peak_held_bytes"] = s.gpu_memory.peak_held_bytes;
  d["gpu_memory_fallbacks"] = s.gpu_memory_fallbacks;
  // How the run was resolved (ResolveRun): the same for the same inputs as
  // on the command line.
  d["run"] = RunToDict(s.run);
  return d;
}

// Runs a database call without the GIL. The progress callback runs on the
// pipeline's writer thread with the GIL taken back; an exception it raises
// (KeyboardInterrupt included) stops the run after the chunks in flight and
// is raised again once the run has returned. (Ctrl-C is only seen by
// Python's main thread, which is inside this call: raise from the callback
// to stop a long run early.)
template <typename Call>
py::dict RunWithProgress(const py::object& progress, Call call) {
  std::atomic<bool> stop{false};
  std::exception_ptr callback_error;
  colmap::MatchingCallbacks callbacks;
  callbacks.stop = &stop;
  // Warnings become Python RuntimeWarnings; where a warnings filter turns
  // them into errors, the run stops and the error is raised.
  callbacks.warning = [&](const std::string& text) {
    py::gil_scoped_acquire gil;
    if (PyErr_WarnEx(PyExc_RuntimeWarning, text.c_str(), 1) < 0 && !callback_error) {
      callback_error = std::make_exception_ptr(py::error_already_set());
      stop = true;
    }
  };
  callbacks.progress = [&](const PipelineProgress& p) {
    py::gil_scoped_acquire gil;
    if (callback_error) return;
    try {
      if (!progress.is_none()) progress(p.pairs_done, p.pairs_total);
    } catch (py::error_already_set&) {
      callback_error = std::current_exception();
      stop = true;
    }
  };
  colmap::MatchingSummary summary;
  {
    py::gil_scoped_release no_gil;
    summary = call(callbacks);
  }
  if (callback_error) std::rethrow_exception(callback_error);
  return SummaryToDict(summary);
}

Camera CameraFromDict(const py::dict& d) {
  Camera camera;
  camera.model_id = d["model_id"].cast<int>();
  camera.width = d["width"].cast<uint64_t>();
  camera.height = d["height"].cast<uint64_t>();
  camera.params = d["params"].cast<std::vector<double>>();
  camera.has_prior_focal_length = d["has_prior_focal_length"].cast<bool>();
  if (CameraModelNumParams(camera.model_id) != static_cast<int>(camera.params.size())) {
    throw std::invalid_argument("camera model " + CameraModelIdToName(camera.model_id) + " takes " +
                                std::to_string(CameraModelNumParams(camera.model_id)) + " parameters, got " +
                                std::to_string(camera.params.size()));
  }
  return camera;
}

py::dict MatchInMemory(const U8Array& descriptors1, const U8Array& descriptors2,
                       const std::optional<F32Array>& keypoints1, const std::optional<F32Array>& keypoints2,
                       const std::optional<py::dict>& camera1, const std::optional<py::dict>& camera2,
                       const MatcherCommandOptions& options) {
  const FeatureDescriptors d1 = ToDescriptors(descriptors1, "descriptors1");
  const FeatureDescriptors d2 = ToDescriptors(descriptors2, "descriptors2");
  const Keypoints k1 = ToKeypoints(keypoints1, "keypoints1");
  const Keypoints k2 = ToKeypoints(keypoints2, "keypoints2");
  std::optional<Camera> c1, c2;
  if (camera1) c1 = CameraFromDict(*camera1);
  if (camera2) c2 = CameraFromDict(*camera2);
  // The pair is checked and resolved as a run of two images is: the same
  // option check (CheckRunOptions), the devices ChooseRunDevices finds
  // (none without use_gpu), ResolveRun, and the matcher CreateMatcherForRun
  // builds; so use_gpu without a usable GPU matches as use_gpu=False does.
  const std::string problem = colmap::CheckRunOptions(options);
  if (!problem.empty()) throw std::invalid_argument(problem);
  colmap::RunFacts facts;
  facts.rows_per_image = {d1.rows(), d2.rows()};
  facts.exhaustive = false;
  facts.gpu_indices = colmap::ChooseRunDevices(options, colmap::MachineDeviceFacts()).gpu_indices;
  const colmap::ResolvedRun run = colmap::ResolveRun(options, facts);
  PairMatchingOptions pair_options;
  pair_options.sift = run.options.sift;
  pair_options.cashash = run.options.cashash;
  pair_options.two_view = options.two_view;
  pair_options.skip_geometric_verification = options.skip_geometric_verification;

  PairMatchingResult result;
  {
    py::gil_scoped_release no_gil;
    const std::unique_ptr<MatchingBackend> matcher =
        colmap::CreateMatcherForRun(run, ComputeMeanDescriptor({&d1, &d2}), nullptr);
    // The run's exact rematch, on this thread: one pair has nothing to
    // overlap it with.
    ExactRematchPolicy policy = run.rematch;
    if (policy.enabled()) policy.where = RematchPlace::kMatchingThread;
    ExactRematchStage rematch(policy, matcher.get());
    const AfterPairMatching after_matching = [&](const std::vector<ImagePair>& pairs,
                                                 std::vector<FeatureMatches>* matches) {
      rematch.AfterMatching(pairs, matches);
    };
    result = MatchImagePair(k1, d1, k2, d2, pair_options, c1 ? &*c1 : nullptr, c2 ? &*c2 : nullptr, matcher.get(),
                            after_matching);
  }
  py::dict out;
  out["matches"] = MatchesToArray(result.matches);
  out["verified"] = result.verified;
  const TwoViewGeometry& g = result.two_view_geometry;
  out["config"] = g.config;
  out["inlier_matches"] = MatchesToArray(g.inlier_matches);
  out["F"] = EigenToArray(g.F);
  out["E"] = EigenToArray(g.E);
  out["H"] = EigenToArray(g.H);
  out["qvec"] = EigenToArray(g.qvec);
  out["tvec"] = EigenToArray(g.tvec);
  out["run"] = RunToDict(run);
  return out;
}

void BindOptions(py::module_& m) {
  py::class_<SiftMatchingOptions>(m, "SiftMatchingOptions")
      .def(py::init<>())
      .def_readwrite("num_threads", &SiftMatchingOptions::num_threads)
      .def_readwrite("max_ratio", &SiftMatchingOptions::max_ratio)
      .def_readwrite("max_distance", &SiftMatchingOptions::max_distance)
      .def_readwrite("cross_check", &SiftMatchingOptions::cross_check)
      .def_readwrite("max_num_matches", &SiftMatchingOptions::max_num_matches);
  // CasHashOptions' own defaults, the one user-facing set (matcher auto,
  // tables, tau and the rematch threshold chosen for the run).
  py::class_<CasHashOptions>(m, "CasHashOptions")
      .def(py::init<>())
      .def_property(
          "matcher", [](const CasHashOptions& o) { return MatcherTypeToString(o.matcher); },
          [](CasHashOptions& o, const std::string& name) {
            if (!MatcherTypeFromString(name, &o.matcher)) {
              throw std::invalid_argument("CasHash.matcher must be 'auto', 'cascade' or 'bruteforce', got '" + name +
                                          "'");
            }
          })
      .def_readwrite("num_tables", &CasHashOptions::num_tables)
      .def_readwrite("bits_per_table", &CasHashOptions::bits_per_table)
      .def_readwrite("tau", &CasHashOptions::tau)
      .def_readwrite("top_k", &CasHashOptions::top_k)
      .def_readwrite("exact_rematch_min_matches", &CasHashOptions::exact_rematch_min_matches)
      .def_readwrite("exact_rematch_max_matches", &CasHashOptions::exact_rematch_max_matches)
      .def_readwrite("random_seed", &CasHashOptions::random_seed);
  py::class_<TwoViewGeometryOptions>(m, "TwoViewGeometryOptions")
      .def(py::init<>())
      .def_readwrite("min_num_inliers", &TwoViewGeometryOptions::min_num_inliers)
      .def_readwrite("min_E_F_inlier_ratio", &TwoViewGeometryOptions::min_E_F_inlier_ratio)
      .def_readwrite("max_H_inlier_ratio", &TwoViewGeometryOptions::max_H_inlier_ratio)
      .def_readwrite("watermark_min_inlier_ratio", &TwoViewGeometryOptions::watermark_min_inlier_ratio)
      .def_readwrite("watermark_border_size", &TwoViewGeometryOptions::watermark_border_size)
      .def_readwrite("detect_watermark", &TwoViewGeometryOptions::detect_watermark)
      .def_readwrite("max_error", &TwoViewGeometryOptions::max_error)
      .def_readwrite("confidence", &TwoViewGeometryOptions::confidence)
      .def_readwrite("min_num_trials", &TwoViewGeometryOptions::min_num_trials)
      .def_readwrite("max_num_trials", &TwoViewGeometryOptions::max_num_trials)
      .def_readwrite("min_inlier_ratio", &TwoViewGeometryOptions::min_inlier_ratio)
      .def_readwrite("random_seed", &TwoViewGeometryOptions::random_seed);
  py::class_<RetrievalOptions>(m, "RetrievalOptions")
      .def(py::init<>())
      .def_readwrite("num_images", &RetrievalOptions::num_images)
      .def_readwrite("num_nearest_neighbors", &RetrievalOptions::num_nearest_neighbors)
      .def_readwrite("max_num_features", &RetrievalOptions::max_num_features)
      .def_readwrite("num_tables", &RetrievalOptions::num_tables)
      .def_readwrite("bits_per_word", &RetrievalOptions::bits_per_word);
  // COLMAP's SequentialMatching.* and SpatialMatching.*, named as pycolmap
  // names them.
  py::class_<SequentialPairingOptions>(m, "SequentialPairingOptions")
      .def(py::init<>())
      .def_readwrite("overlap", &SequentialPairingOptions::overlap)
      .def_readwrite("quadratic_overlap", &SequentialPairingOptions::quadratic_overlap)
      .def_readwrite("expand_rig_images", &SequentialPairingOptions::expand_rig_images)
      .def_readwrite("loop_detection", &SequentialPairingOptions::loop_detection)
      .def_readwrite("loop_detection_period", &SequentialPairingOptions::loop_detection_period)
      .def_readwrite("loop_detection_num_images", &SequentialPairingOptions::loop_detection_num_images)
      .def_readwrite("loop_detection_min_index_distance", &SequentialPairingOptions::loop_detection_min_index_distance)
      .def_readwrite("loop_detection_num_nearest_neighbors",
                     &SequentialPairingOptions::loop_detection_num_nearest_neighbors)
      .def_readwrite("loop_detection_num_checks", &SequentialPairingOptions::loop_detection_num_checks)
      .def_readwrite("loop_detection_num_images_after_verification",
                     &SequentialPairingOptions::loop_detection_num_images_after_verification)
      .def_readwrite("loop_detection_max_num_features", &SequentialPairingOptions::loop_detection_max_num_features)
      .def_readwrite("vocab_tree_path", &SequentialPairingOptions::vocab_tree_path)
      .def_readwrite("num_threads", &SequentialPairingOptions::num_threads)
      .def("check", &SequentialPairingOptions::Check);
  py::class_<SpatialPairingOptions>(m, "SpatialPairingOptions")
      .def(py::init<>())
      .def_readwrite("ignore_z", &SpatialPairingOptions::ignore_z)
      .def_readwrite("max_num_neighbors", &SpatialPairingOptions::max_num_neighbors)
      .def_readwrite("min_num_neighbors", &SpatialPairingOptions::min_num_neighbors)
      .def_readwrite("max_distance", &SpatialPairingOptions::max_distance)
      .def_readwrite("is_gps", &SpatialPairingOptions::is_gps)
      .def_readwrite("num_threads", &SpatialPairingOptions::num_threads)
      .def("check", &SpatialPairingOptions::Check);
  py::class_<MatcherCommandOptions>(m, "MatchingOptions")
      .def(py::init<>())
      .def_readwrite("sift", &MatcherCommandOptions::sift)
      .def_readwrite("cashash", &MatcherCommandOptions::cashash)
      .def_readwrite("two_view", &MatcherCommandOptions::two_view)
      .def_readwrite("retrieval", &MatcherCommandOptions::retrieval)
      .def_readwrite("vocab_tree_path", &MatcherCommandOptions::vocab_tree_path)
      .def_readwrite("transitive_rounds", &MatcherCommandOptions::transitive_rounds)
      .def_readwrite("sequential", &MatcherCommandOptions::sequential)
      .def_readwrite("spatial", &MatcherCommandOptions::spatial)
      .def_readwrite("block_size", &MatcherCommandOptions::block_size)
      .def_readwrite("use_gpu", &MatcherCommandOptions::use_gpu)
      .def_readwrite("gpu_index", &MatcherCommandOptions::gpu_index)
      .def_readwrite("skip_geometric_verification", &MatcherCommandOptions::skip_geometric_verification)
      .def_readwrite("overwrite", &MatcherCommandOptions::overwrite)
      .def_readwrite("write_empty_pairs", &MatcherCommandOptions::write_empty_pairs)
      .def_readwrite("database_commit_seconds", &MatcherCommandOptions::database_commit_seconds)
      .def_readwrite("database_synchronous", &MatcherCommandOptions::database_synchronous)
      .def_readwrite("max_host_memory", &MatcherCommandOptions::max_host_memory)
      .def_readwrite("max_gpu_memory", &MatcherCommandOptions::max_gpu_memory)
      .def_readwrite("pipeline_trace_path", &MatcherCommandOptions::pipeline_trace_path)
      .def_readwrite("gpu_verifications_in_flight", &MatcherCommandOptions::gpu_verifications_in_flight);
}

}  // namespace
}  // namespace cashash

PYBIND11_MODULE(_core, m) {
  using namespace cashash;
  m.doc() = "Cascade Hashing feature matching for COLMAP databases (C++ core)";
  BindOptions(m);
  m.def(
      "match_exhaustive",
      [](const std::string& database_path, const MatcherCommandOptions& options, const py::object& progress) {
        return RunWithProgress(progress, [&](const colmap::MatchingCallbacks& callbacks) {
          return colmap::MatchExhaustive(database_path, options, callbacks);
        });
      },
      py::arg("database_path"), py::arg("options"), py::arg("progress") = py::none());
  m.def(
      "match_pairs",
      [](const std::string& database_path, const std::vector<std::pair<std::string, std::string>>& pairs,
         const MatcherCommandOptions& options, const py::object& progress) {
        return RunWithProgress(progress, [&](const colmap::MatchingCallbacks& callbacks) {
          return colmap::MatchPairs(database_path, pairs, options, callbacks);
        });
      },
      py::arg("database_path"), py::arg("pairs"), py::arg("options"), py::arg("progress") = py::none());
  m.def(
      "match_retrieval",
      [](const std::string& database_path, const MatcherCommandOptions& options, const py::object& progress) {
        return RunWithProgress(progress, [&](const colmap::MatchingCallbacks& callbacks) {
          return colmap::MatchRetrieval(database_path, options, callbacks);
        });
      },
      py::arg("database_path"), py::arg("options"), py::arg("progress") = py::none());
  m.def(
      "match_sequential",
      [](const std::string& database_path, const MatcherCommandOptions& options, const py::object& progress) {
        return RunWithProgress(progress, [&](const colmap::MatchingCallbacks& callbacks) {
          return colmap::MatchSequential(database_path, options, callbacks);
        });
      },
      py::arg("database_path"), py::arg("options"), py::arg("progress") = py::none());
  m.def(
      "match_spatial",
      [](const std::string& database_path, const MatcherCommandOptions& options, const py::object& progress) {
        return RunWithProgress(progress, [&](const colmap::MatchingCallbacks& callbacks) {
          return colmap::MatchSpatial(database_path, options, callbacks);
        });
      },
      py::arg("database_path"), py::arg("options"), py::arg("progress") = py::none());
  m.def("match", &MatchInMemory, py::arg("descriptors1"), py::arg("descriptors2"), py::arg("keypoints1"),
        py::arg("keypoints2"), py::arg("camera1"), py::arg("camera2"), py::arg("options"));
  m.def("build_info", []() {
    const colmap::BuildInfo info = colmap::GetBuildInfo();
    py::dict out;
    out["version"] = info.version;
    out["cuda"] = info.cuda;
    out["cuda_sass"] = info.cuda_sass;
    out["cuda_ptx"] = info.cuda_ptx;
    out["cuda_architectures"] = info.cuda_architectures;
    return out;
  });
  m.def("camera_model_name", &CameraModelIdToName, py::arg("model_id"));
  m.def("camera_model_num_params", &CameraModelNumParams, py::arg("model_id"));
  m.attr("with_cuda") =
#ifdef CASHASH_WITH_CUDA
      true;
#else
      false;
#endif
}
