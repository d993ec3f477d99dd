#pragma once
// The viewer's page and script (apps/tofcam/viewer/web), embedded at build time by
// embed_web.cmake so `tofcam view` needs no source tree.

namespace tofcam::viewer::assets {

extern const char kIndexHtml[];
extern const char kViewerJs[];

}  // namespace tofcam::viewer::assets
