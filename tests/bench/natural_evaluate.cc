// natural-evaluate: the natural-scene evaluation of tests/bench/natural_tables.h.
#include "tests/bench/natural_tables.h"

int main(int argc, char** argv) { return inspection::RunNaturalEvaluation(argc, argv); }
