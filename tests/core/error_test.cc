#include "tofcam/core/error.h"

#include <gtest/gtest.h>

#include <set>

namespace tofcam {
namespace {

constexpr ErrorCode kCodes[] = {
    ErrorCode::kInvalidArgument, ErrorCode::kNotFound,    ErrorCode::kIo,      ErrorCode::kFormat,
    ErrorCode::kMismatch,        ErrorCode::kUnsupported, ErrorCode::kInternal};

TEST(ErrorTest, CarriesCodeAndMessage) {
  const Error e(ErrorCode::kFormat, "calib.yaml: line 3: bad matrix");
  EXPECT_EQ(e.code(), ErrorCode::kFormat);
  EXPECT_STREQ(e.what(), "calib.yaml: line 3: bad matrix");
  const std::runtime_error& base = e;  // catchable as a standard exception
  EXPECT_STREQ(base.what(), "calib.yaml: line 3: bad matrix");
}

TEST(ErrorTest, CodesHaveDistinctNamesAndExitStatuses) {
  std::set<std::string_view> names;
  std::set<int> statuses;
  for (ErrorCode c : kCodes) {
    EXPECT_TRUE(names.insert(ErrorCodeName(c)).second);
    const int s = ExitStatus(c);
    EXPECT_GE(s, 2);  // 0 is success, 1 is CLI11's usage error
    EXPECT_LE(s, 9);
    EXPECT_TRUE(statuses.insert(s).second);
  }
  EXPECT_EQ(ErrorCodeName(ErrorCode::kInvalidArgument), "invalid-argument");
  EXPECT_EQ(ErrorCodeName(ErrorCode::kNotFound), "not-found");
}

}  // namespace
}  // namespace tofcam
