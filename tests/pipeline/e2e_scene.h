#pragma once
// Moved to tests/support/bump_scene.h (u3mscan_test_support). Kept only for tests/stability, which
// still includes this path; switch it to the support header and delete this file.
#include "tests/support/bump_scene.h"
