// The program whose build makes the unit tests' shared precompiled header (tests/CMakeLists.txt).
int main() { return 0; }
