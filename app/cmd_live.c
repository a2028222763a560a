/* bitfuse live: the reconstruction pipeline on a live source. Until the
 * tracking pipeline takes live input it records the source to
 * DIR/capture.bflog (saying so), exactly as `bitfuse record` does. */
#include "app.h"

int cmd_live(int argc, char **argv) { return app_record("live", argc, argv, true); }
