/* bitfuse live: the reconstruction loop on a live source (cmd_replay.c
 * holds the loop; the device comes through the capture thread). */
#include "app.h"

int cmd_live(int argc, char **argv) { return app_reconstruct("live", argc, argv, true); }
