#include "sim_core/version.h"
