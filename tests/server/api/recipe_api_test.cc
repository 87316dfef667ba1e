// Recipes through the real server: create, versioned update with
// optimistic locking, get by version, list, delete; every bad document refused with
// INVALID_ARGUMENT naming the field and nothing stored; unknown ids and versions NOT_FOUND.
// The camera is 320 x 240 px (ServerTest::SimOptions), which bounds the regions.
#include <google/protobuf/util/json_util.h>
#include <gtest/gtest.h>

#include <cmath>

#include "server/results/recipe_mapping.h"
#include "tests/server/server_fixture.h"

namespace inspection::testing {
namespace {

// A step height between two pads and Sa on a polygon, as an engineer would write it.
v1::Recipe PadRecipe(const std::string& id = "pad-check") {
  v1::Recipe r;
  const std::string json = R"({
    "recipe_id": ")" + id + R"(",
    "description": "pad height and roughness",
    "scan": {"z_step_um": 5, "illumination": "ILLUMINATION_MODE_STD"},
    "measurements": [
      {"name": "pad_height", "parameter": "step_height",
       "roi": {"shape": "SHAPE_RECTANGLE", "x": 20, "y": 20, "width": 100, "height": 80},
       "reference_roi": {"shape": "SHAPE_RECTANGLE", "x": 180, "y": 20, "width": 100, "height": 80},
       "tolerance": {"nominal": 12.5, "lower": -0.5, "upper": 0.5, "min_coverage_percent": 80}},
      {"name": "pad_sa", "parameter": "Sa", "s_filter_um": 2.5, "l_filter_um": 80,
       "roi": {"shape": "SHAPE_POLYGON", "unit": "um",
               "polygon": [{"x": 10, "y": 10}, {"x": 100, "y": 10}, {"x": 60, "y": 90}]},
       "tolerance": {"upper": 0.8}}
    ]})";
  EXPECT_TRUE(google::protobuf::util::JsonStringToMessage(json, &r).ok());
  return r;
}

class RecipeApiTest : public ServerTest {
 protected:
  void SetUp() override {
    ServerTest::SetUp();
    StartServer();
  }
  // The status of creating `r`, which must fail; nothing may be stored.
  grpc::Status CreateFails(const v1::Recipe& r) {
    v1::Recipe stored;
    grpc::Status s = client_->CreateRecipe(r, &stored);
    EXPECT_FALSE(s.ok());
    v1::ListRecipesResponse list;
    EXPECT_TRUE(client_->ListRecipes(&list).ok());
    EXPECT_EQ(list.recipes_size(), 0) << "a refused recipe was stored";
    return s;
  }
  void ExpectInvalidNaming(const v1::Recipe& r, const std::string& field) {
    const grpc::Status s = CreateFails(r);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << s.error_message();
    EXPECT_NE(s.error_message().find(field), std::string::npos) << "'" << s.error_message() << "' names not " << field;
  }
};

TEST_F(RecipeApiTest, VersionsAreKeptAndUpdatesNeedTheCurrentVersion) {
  v1::Recipe stored;
  ASSERT_TRUE(client_->CreateRecipe(PadRecipe(), &stored).ok());
  EXPECT_EQ(stored.version(), 1);
  EXPECT_EQ(stored.author(), "anonymous");
  EXPECT_GT(stored.create_time().seconds(), 0);
  EXPECT_EQ(stored.measurements_size(), 2);

  v1::Recipe second = PadRecipe();
  second.mutable_measurements(0)->mutable_tolerance()->set_nominal(13.0);
  ASSERT_TRUE(client_->UpdateRecipe(second, /*expected_version=*/1, &stored).ok());
  EXPECT_EQ(stored.version(), 2);
  // Someone who still holds version 1 cannot overwrite version 2 unseen.
  grpc::Status s = client_->UpdateRecipe(PadRecipe(), 1, &stored);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::ABORTED) << s.error_message();
  EXPECT_NE(s.error_message().find("version 2"), std::string::npos) << s.error_message();

  v1::Recipe got;
  ASSERT_TRUE(client_->GetRecipe("pad-check", 0, &got).ok());
  EXPECT_EQ(got.version(), 2);
  EXPECT_DOUBLE_EQ(got.measurements(0).tolerance().nominal(), 13.0);
  ASSERT_TRUE(client_->GetRecipe("pad-check", 1, &got).ok());
  EXPECT_DOUBLE_EQ(got.measurements(0).tolerance().nominal(), 12.5);
  EXPECT_TRUE(got.measurements(1).tolerance().has_upper());
  EXPECT_FALSE(got.measurements(1).tolerance().has_lower());

  ASSERT_TRUE(client_->CreateRecipe(PadRecipe("lens-radius-a"), &stored).ok());
  v1::ListRecipesResponse list;
  ASSERT_TRUE(client_->ListRecipes(&list).ok());
  ASSERT_EQ(list.recipes_size(), 2);
  EXPECT_EQ(list.recipes(0).recipe_id(), "lens-radius-a");
  EXPECT_EQ(list.recipes(1).recipe_id(), "pad-check");
  EXPECT_EQ(list.recipes(1).version(), 2);

  s = client_->CreateRecipe(PadRecipe(), &stored);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::ALREADY_EXISTS) << s.error_message();
}

TEST_F(RecipeApiTest, DeletedRecipesAreGoneButTheirNumbersAreNeverReused) {
  v1::Recipe stored;
  ASSERT_TRUE(client_->CreateRecipe(PadRecipe(), &stored).ok());
  ASSERT_TRUE(client_->UpdateRecipe(PadRecipe(), 0, &stored).ok());
  v1::DeleteResponse deleted;
  ASSERT_TRUE(client_->DeleteRecipe("pad-check", &deleted).ok());
  EXPECT_EQ(deleted.id(), "pad-check");
  v1::Recipe got;
  EXPECT_EQ(client_->GetRecipe("pad-check", 0, &got).error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_EQ(client_->UpdateRecipe(PadRecipe(), 0, &stored).error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_EQ(client_->DeleteRecipe("pad-check", &deleted).error_code(), grpc::StatusCode::NOT_FOUND);
  // Results that ran version 2 can still read it; a recreated recipe starts at version 3.
  ASSERT_TRUE(client_->GetRecipe("pad-check", 2, &got).ok());
  ASSERT_TRUE(client_->CreateRecipe(PadRecipe(), &stored).ok());
  EXPECT_EQ(stored.version(), 3);
}

TEST_F(RecipeApiTest, UnknownIdsAndVersionsAreNotFound) {
  v1::Recipe got;
  grpc::Status s = client_->GetRecipe("no-such-recipe", 0, &got);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_NE(s.error_message().find("no-such-recipe"), std::string::npos);
  v1::Recipe stored;
  ASSERT_TRUE(client_->CreateRecipe(PadRecipe(), &stored).ok());
  s = client_->GetRecipe("pad-check", 7, &got);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_NE(s.error_message().find("version 7"), std::string::npos) << s.error_message();
  s = client_->GetRecipe("../etc", 0, &got);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
}

TEST_F(RecipeApiTest, BadDocumentsNameTheFieldAndStoreNothing) {
  v1::Recipe r = PadRecipe();
  r.mutable_measurements(0)->mutable_roi()->set_x(300);  // 300 + 100 > 320 px
  ExpectInvalidNaming(r, "recipe.measurements[0].roi");

  r = PadRecipe();
  r.mutable_measurements(1)->mutable_roi()->clear_polygon();
  ExpectInvalidNaming(r, "recipe.measurements[1].roi.polygon");

  r = PadRecipe();
  r.mutable_measurements(0)->mutable_tolerance()->set_lower(0.7);  // above upper 0.5
  ExpectInvalidNaming(r, "recipe.measurements[0].tolerance");

  r = PadRecipe();
  r.mutable_measurements(1)->clear_tolerance();
  ExpectInvalidNaming(r, "recipe.measurements[1].tolerance is required");

  r = PadRecipe();
  r.mutable_measurements(1)->set_parameter("Sx");
  ExpectInvalidNaming(r, "recipe.measurements[1].parameter");

  r = PadRecipe();
  r.mutable_measurements(0)->set_l_filter_um(80);  // an L-filter means nothing to a step height
  ExpectInvalidNaming(r, "recipe.measurements[0].l_filter_um");

  r = PadRecipe();
  r.mutable_measurements(0)->clear_reference_roi();
  ExpectInvalidNaming(r, "recipe.measurements[0].reference_roi");

  r = PadRecipe();
  r.mutable_measurements(1)->set_name("pad_height");
  ExpectInvalidNaming(r, "recipe.measurements[1].name");

  r = PadRecipe();
  r.mutable_measurements(1)->mutable_roi()->set_unit("inch");
  ExpectInvalidNaming(r, "recipe.measurements[1].roi.unit");

  r = PadRecipe("../../etc/passwd");
  ExpectInvalidNaming(r, "recipe.recipe_id");

  r = PadRecipe();
  r.clear_measurements();
  ExpectInvalidNaming(r, "recipe.measurements");

  r = PadRecipe();
  r.mutable_scan()->set_z_step_um(-1);
  ExpectInvalidNaming(r, "recipe.scan: z_step_um");

  r = PadRecipe();
  r.set_description(std::string(300, 'x'));
  ExpectInvalidNaming(r, "recipe.description");

  r = PadRecipe();
  r.set_version(4);
  ExpectInvalidNaming(r, "recipe.version");

  // Oversized: 64 measurements, each on a 1000-vertex polygon (about 1 MB serialised).
  r = PadRecipe();
  r.clear_measurements();
  for (int i = 0; i < kMaxRecipeMeasurements; ++i) {
    v1::RecipeMeasurement* m = r.add_measurements();
    m->set_name("m" + std::to_string(i));
    m->set_parameter("Sa");
    m->mutable_roi()->set_shape(v1::RecipeRegion::SHAPE_POLYGON);
    for (int k = 0; k < 1000; ++k) {
      auto* p = m->mutable_roi()->add_polygon();
      p->set_x(160 + 100 * std::cos(k * 0.00628318 + 0.1234567));
      p->set_y(120 + 100 * std::sin(k * 0.00628318 + 0.1234567));
    }
  }
  const grpc::Status s = CreateFails(r);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << s.error_message();
  EXPECT_EQ(s.error_message().rfind("recipe is ", 0), 0u) << s.error_message();
  EXPECT_NE(s.error_message().find("at most 262144"), std::string::npos) << s.error_message();
}

TEST_F(RecipeApiTest, UpdatesAreCheckedLikeCreations) {
  v1::Recipe stored;
  ASSERT_TRUE(client_->CreateRecipe(PadRecipe(), &stored).ok());
  v1::Recipe bad = PadRecipe();
  bad.mutable_measurements(0)->mutable_tolerance()->clear_lower();
  bad.mutable_measurements(0)->mutable_tolerance()->clear_upper();
  grpc::Status s = client_->UpdateRecipe(bad, 0, &stored);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(s.error_message().find("recipe.measurements[0].tolerance"), std::string::npos) << s.error_message();
  v1::Recipe got;
  ASSERT_TRUE(client_->GetRecipe("pad-check", 0, &got).ok());
  EXPECT_EQ(got.version(), 1);  // the refused update stored nothing
}

}  // namespace
}  // namespace inspection::testing
