// terrane-view: the Terrane rendering client (client/view/VIEWER.md).
#include "client/view/app/viewer_app.h"

int main(int argc, char** argv) {
  terrane::view::ViewerOptions options;
  const int rc = terrane::view::parse_viewer_options(argc, argv, options);
  if (rc < 0) return 0;
  if (rc != 0) return rc;
  return options.screenshot.empty() ? terrane::view::run_window(options) : terrane::view::run_screenshot(options);
}
