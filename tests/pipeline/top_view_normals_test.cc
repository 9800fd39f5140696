// The pieces of a tilted capture's top-view normal refinement (pipeline/top_view_normals.h): the
// cluster model's noise levels carried over to the top view's observations, and when it runs.
#include "pipeline/top_view_normals.h"

#include <gtest/gtest.h>

#include <stdexcept>
#include <string>

namespace u3mscan {
namespace {

// Two cameras ("top", "oblique") and three lights; one observation per (camera, light), the
// oblique camera's first, as a side's stack lists them.
Stack TwoCameraStack() {
  Stack stack;
  stack.grid = {2, 2, 0.1, 0.0, 0.2};
  for (const char* id : {"L00", "L01", "L02"}) {
    LightModel light;
    light.id = id;
    stack.lights.push_back(light);
  }
  stack.views = {{"oblique", {500, 0, 900}}, {"top", {0, 0, 1000}}};
  for (int view : {0, 1}) {
    for (int light = 0; light < 3; ++light) {
      Observation o;
      o.view = view;
      o.light = light;
      o.rgb = Image(2, 2, 3, 0.5f, 0.1);
      stack.observations.push_back(std::move(o));
    }
  }
  return stack;
}

TEST(TopViewNormals, TheModelTakesEachObservationsNoiseLevelByLightAndCamera) {
  const Stack fitted = TwoCameraStack();
  fitting::ClusterModel model;
  model.options.refine_pixel_normals = false;  // as a tilted view's fit has it
  model.options.mode = fitting::FitMode::kPerPixel;
  for (std::size_t i = 0; i < fitted.observations.size(); ++i) model.observation_levels.push_back(10.0 + i);
  // The top view's observations in another order, and in a stack whose views are numbered
  // otherwise (the fine stack of one view holds that view alone).
  Stack top;
  top.grid = {4, 4, 0.05, 0.0, 0.2};
  top.lights = fitted.lights;
  top.views = {{"top", {0, 0, 1000}}};
  for (int light : {2, 0}) {
    Observation o;
    o.view = 0;
    o.light = light;
    top.observations.push_back(std::move(o));
  }
  const fitting::ClusterModel refining = ModelForTopViewNormals(model, fitted, top);
  EXPECT_TRUE(refining.options.refine_pixel_normals);
  EXPECT_EQ(refining.options.mode, fitting::FitMode::kClusters);  // the normals alone are kept
  // fitted: oblique L00..L02 are 10, 11, 12; top L00..L02 are 13, 14, 15.
  ASSERT_EQ(refining.observation_levels.size(), 2u);
  EXPECT_EQ(refining.observation_levels[0], 15.0);
  EXPECT_EQ(refining.observation_levels[1], 13.0);
  EXPECT_FALSE(model.options.refine_pixel_normals);  // the fit's own model is not changed

  // An observation the fit did not have: refused, the light and camera named.
  top.lights.push_back(LightModel{.id = "L07"});
  Observation stranger;
  stranger.light = 3;
  top.observations.push_back(std::move(stranger));
  try {
    ModelForTopViewNormals(model, fitted, top);
    ADD_FAILURE() << "an observation the fit did not have was accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("light L07 of camera top"), std::string::npos) << e.what();
  }
  // A model whose levels are not the fitted stack's observations.
  model.observation_levels.pop_back();
  EXPECT_THROW(ModelForTopViewNormals(model, fitted, top), std::invalid_argument);
}

TEST(TopViewNormals, RefinesOnlyATiltedViewsNormalsOnAFinerGrid) {
  StageOptions options;
  options.photometric_stereo.view = 1;  // UseTheMostVerticalViewForNormals set it
  EXPECT_TRUE(RefinesTopViewNormals(options, 2));
  EXPECT_FALSE(RefinesTopViewNormals(options, 1));  // no finer grid
  options.refine_top_view_normals = false;           // --no-top-view-refinement
  EXPECT_FALSE(RefinesTopViewNormals(options, 2));
  options.refine_top_view_normals = true;
  options.photometric_stereo.view = -1;  // every view: no tilted view
  EXPECT_FALSE(RefinesTopViewNormals(options, 2));
}

}  // namespace
}  // namespace u3mscan
