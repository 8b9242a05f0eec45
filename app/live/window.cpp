#include "app/live/window.h"

#define GLFW_INCLUDE_NONE
#define GL_GLEXT_PROTOTYPES
#include <GL/glcorearb.h>
#include <GLFW/glfw3.h>
#include <backends/imgui_impl_glfw.h>
#include <backends/imgui_impl_opengl3.h>
#include <imgui.h>

#include <algorithm>
#include <cstdint>
#include <cstdlib>
#include <mutex>
#include <optional>
#include <stdexcept>

namespace nerfar {
namespace {

const char* kVertexShader = R"(#version 330 core
layout(location = 0) in vec2 position;  // unit quad corner, 0..1
uniform vec4 rect;                      // x0, y0, width, height in clip space
out vec2 uv;
void main() {
  uv = position;
  gl_Position = vec4(rect.xy + position * rect.zw, 0.0, 1.0);
})";

const char* kFragmentShader = R"(#version 330 core
in vec2 uv;
uniform sampler2D image;
out vec4 colour;
void main() { colour = vec4(texture(image, vec2(uv.x, 1.0 - uv.y)).rgb, 1.0); })";

GLuint CompileShader(GLenum type, const char* source) {
  const GLuint shader = glCreateShader(type);
  glShaderSource(shader, 1, &source, nullptr);
  glCompileShader(shader);
  GLint ok = 0;
  glGetShaderiv(shader, GL_COMPILE_STATUS, &ok);
  if (!ok) {
    char log[1024];
    glGetShaderInfoLog(shader, sizeof log, nullptr, log);
    throw std::runtime_error(std::string("live window: shader does not compile: ") + log);
  }
  return shader;
}

// The finished frame in the back buffer, before it is swapped away, as RGB
// with the origin at the top-left.
Image8 ReadBackBuffer(int width, int height) {
  Image8 image(width, height, 3);
  std::vector<std::uint8_t> bottom_up(image.pixels.size());
  glPixelStorei(GL_PACK_ALIGNMENT, 1);
  glReadBuffer(GL_BACK);
  glReadPixels(0, 0, width, height, GL_RGB, GL_UNSIGNED_BYTE, bottom_up.data());
  for (int y = 0; y < height; ++y)
    std::copy_n(bottom_up.data() + static_cast<size_t>(height - 1 - y) * width * 3, static_cast<size_t>(width) * 3,
                image.Pixel(0, y));
  return image;
}

struct ViewRect {
  double x0, y0, width, height;  // window pixels, origin top-left
  int image_width, image_height;
};

}  // namespace

struct LiveWindow::Impl {
  GLFWwindow* window = nullptr;
  GLuint program = 0, vao = 0, vbo = 0;
  std::vector<GLuint> textures;
  // What each texture holds: the image it was uploaded from (its pixels'
  // address) and its size, to upload a view only when it is new.
  struct Uploaded {
    const std::uint8_t* pixels = nullptr;
    int width = 0, height = 0, channels = 0;
  };
  std::vector<Uploaded> uploaded;
  std::vector<ViewRect> rects;
  std::vector<InputEvent> events;
  bool dragging = false;
  int drag_button = 0;
  double cursor_x = 0, cursor_y = 0;
  bool capture_requested = false;
  std::optional<Image8> capture;

  InputEvent MouseEvent(InputEvent::Kind kind, double wx, double wy, int button) const {
    InputEvent event;
    event.kind = kind;
    event.button = button;
    for (size_t v = 0; v < rects.size(); ++v) {
      const ViewRect& r = rects[v];
      if (wx < r.x0 || wy < r.y0 || wx >= r.x0 + r.width || wy >= r.y0 + r.height) continue;
      event.view = static_cast<int>(v);
      event.x = (wx - r.x0) / r.width * r.image_width;
      event.y = (wy - r.y0) / r.height * r.image_height;
    }
    if (window != nullptr) {
      event.shift = glfwGetKey(window, GLFW_KEY_LEFT_SHIFT) == GLFW_PRESS;
      event.control = glfwGetKey(window, GLFW_KEY_LEFT_CONTROL) == GLFW_PRESS;
    }
    return event;
  }

  void HandleMouse(InputEvent::Kind kind, double wx, double wy, int button) {
    cursor_x = wx;
    cursor_y = wy;
    if (kind == InputEvent::Kind::kPress) {
      dragging = true;
      drag_button = button;
    } else if (kind == InputEvent::Kind::kRelease) {
      dragging = false;
    } else if (kind == InputEvent::Kind::kDrag && !dragging) {
      return;
    }
    events.push_back(MouseEvent(kind, wx, wy, kind == InputEvent::Kind::kDrag ? drag_button : button));
  }
};

namespace {
LiveWindow::Impl* ImplOf(GLFWwindow* window) {
  return static_cast<LiveWindow::Impl*>(glfwGetWindowUserPointer(window));
}
bool ImGuiWantsMouse() { return ImGui::GetCurrentContext() != nullptr && ImGui::GetIO().WantCaptureMouse; }
int GlfwButton(int button) {
  return button == GLFW_MOUSE_BUTTON_RIGHT ? 1 : (button == GLFW_MOUSE_BUTTON_MIDDLE ? 2 : 0);
}
std::once_flag g_glfw_init_once;
bool g_glfw_ok = false;
}  // namespace

bool LiveWindow::DisplayAvailable() {
  const char* display = std::getenv("DISPLAY");
  const char* wayland = std::getenv("WAYLAND_DISPLAY");
  if ((display == nullptr || *display == '\0') && (wayland == nullptr || *wayland == '\0')) return false;
  std::call_once(g_glfw_init_once, [] { g_glfw_ok = glfwInit() == GLFW_TRUE; });
  return g_glfw_ok;
}

LiveWindow::LiveWindow(const std::string& title, int width, int height) : impl_(std::make_unique<Impl>()) {
  if (!DisplayAvailable()) throw std::runtime_error("no display (DISPLAY is unset or GLFW cannot start)");
  glfwWindowHint(GLFW_CONTEXT_VERSION_MAJOR, 3);
  glfwWindowHint(GLFW_CONTEXT_VERSION_MINOR, 3);
  glfwWindowHint(GLFW_OPENGL_PROFILE, GLFW_OPENGL_CORE_PROFILE);
  glfwWindowHint(GLFW_OPENGL_FORWARD_COMPAT, GLFW_TRUE);
  impl_->window = glfwCreateWindow(width, height, title.c_str(), nullptr, nullptr);
  if (impl_->window == nullptr) throw std::runtime_error("cannot open an OpenGL 3.3 core window");
  glfwMakeContextCurrent(impl_->window);
  glfwSwapInterval(1);
  glfwSetWindowUserPointer(impl_->window, impl_.get());

  IMGUI_CHECKVERSION();
  ImGui::CreateContext();
  ImGui::GetIO().IniFilename = nullptr;  // no imgui.ini in the user's folder
  ImGui::StyleColorsDark();
  // Our callbacks are installed first; ImGui chains to them.
  glfwSetMouseButtonCallback(impl_->window, [](GLFWwindow* w, int button, int action, int) {
    if (ImGuiWantsMouse()) return;
    // The position tracked from motion events, in event order (glfwGetCursorPos
    // would ask the server for where the pointer is now).
    Impl* impl = ImplOf(w);
    impl->HandleMouse(action == GLFW_PRESS ? InputEvent::Kind::kPress : InputEvent::Kind::kRelease, impl->cursor_x,
                      impl->cursor_y, GlfwButton(button));
  });
  glfwSetCursorPosCallback(impl_->window, [](GLFWwindow* w, double x, double y) {
    ImplOf(w)->HandleMouse(InputEvent::Kind::kDrag, x, y, 0);
  });
  glfwSetScrollCallback(impl_->window, [](GLFWwindow* w, double, double dy) {
    if (ImGuiWantsMouse()) return;
    Impl* impl = ImplOf(w);
    InputEvent event = impl->MouseEvent(InputEvent::Kind::kScroll, impl->cursor_x, impl->cursor_y, 0);
    event.scroll = dy;
    impl->events.push_back(event);
  });
  glfwSetKeyCallback(impl_->window, [](GLFWwindow* w, int key, int, int action, int mods) {
    if (action != GLFW_PRESS || (ImGui::GetCurrentContext() && ImGui::GetIO().WantCaptureKeyboard)) return;
    InputEvent event;
    event.kind = InputEvent::Kind::kKey;
    event.key = key == GLFW_KEY_ESCAPE ? kKeyEscape : key == GLFW_KEY_TAB ? kKeyTab : key == GLFW_KEY_F1 ? kKeyF1 : key;
    event.shift = (mods & GLFW_MOD_SHIFT) != 0;
    event.control = (mods & GLFW_MOD_CONTROL) != 0;
    ImplOf(w)->events.push_back(event);
  });
  glfwGetCursorPos(impl_->window, &impl_->cursor_x, &impl_->cursor_y);
  ImGui_ImplGlfw_InitForOpenGL(impl_->window, true);
  ImGui_ImplOpenGL3_Init("#version 330 core");

  const GLuint vs = CompileShader(GL_VERTEX_SHADER, kVertexShader);
  const GLuint fs = CompileShader(GL_FRAGMENT_SHADER, kFragmentShader);
  impl_->program = glCreateProgram();
  glAttachShader(impl_->program, vs);
  glAttachShader(impl_->program, fs);
  glLinkProgram(impl_->program);
  glDeleteShader(vs);
  glDeleteShader(fs);
  const float quad[] = {0, 0, 1, 0, 0, 1, 1, 1};
  glGenVertexArrays(1, &impl_->vao);
  glBindVertexArray(impl_->vao);
  glGenBuffers(1, &impl_->vbo);
  glBindBuffer(GL_ARRAY_BUFFER, impl_->vbo);
  glBufferData(GL_ARRAY_BUFFER, sizeof quad, quad, GL_STATIC_DRAW);
  glEnableVertexAttribArray(0);
  glVertexAttribPointer(0, 2, GL_FLOAT, GL_FALSE, 0, nullptr);
}

LiveWindow::~LiveWindow() {
  if (impl_->window == nullptr) return;
  glfwMakeContextCurrent(impl_->window);
  ImGui_ImplOpenGL3_Shutdown();
  ImGui_ImplGlfw_Shutdown();
  ImGui::DestroyContext();
  if (!impl_->textures.empty()) glDeleteTextures(static_cast<GLsizei>(impl_->textures.size()), impl_->textures.data());
  glDeleteBuffers(1, &impl_->vbo);
  glDeleteVertexArrays(1, &impl_->vao);
  glDeleteProgram(impl_->program);
  glfwDestroyWindow(impl_->window);
}

bool LiveWindow::ShouldClose() const { return glfwWindowShouldClose(impl_->window) == GLFW_TRUE; }
void LiveWindow::RequestClose() { glfwSetWindowShouldClose(impl_->window, GLFW_TRUE); }

namespace {
// `image` into the bound texture, unless it holds it already (the same
// image, unchanged: `changed` false): a new image of the texture's size
// replaces its pixels in place, one of another size reallocates it.
void UploadView(const Image8& image, bool changed, LiveWindow::Impl::Uploaded& held) {
  const bool same_size = held.width == image.width && held.height == image.height && held.channels == image.channels;
  if (!changed && same_size && held.pixels == image.pixels.data()) return;
  glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
  const GLenum format = image.channels == 1 ? GL_RED : (image.channels == 4 ? GL_RGBA : GL_RGB);
  if (same_size) {
    glTexSubImage2D(GL_TEXTURE_2D, 0, 0, 0, image.width, image.height, format, GL_UNSIGNED_BYTE, image.pixels.data());
  } else {
    glTexImage2D(GL_TEXTURE_2D, 0, GL_RGB8, image.width, image.height, 0, format, GL_UNSIGNED_BYTE,
                 image.pixels.data());
    const GLint grey[] = {GL_RED, GL_RED, GL_RED, GL_ONE}, colour[] = {GL_RED, GL_GREEN, GL_BLUE, GL_ALPHA};
    glTexParameteriv(GL_TEXTURE_2D, GL_TEXTURE_SWIZZLE_RGBA, image.channels == 1 ? grey : colour);
  }
  held = {image.pixels.data(), image.width, image.height, image.channels};
}
}  // namespace

std::vector<InputEvent> LiveWindow::Present(const std::vector<const Image8*>& views,
                                            const std::function<void()>& draw_controls, bool new_views) {
  glfwPollEvents();
  int fb_width = 0, fb_height = 0, win_width = 0, win_height = 0;
  glfwGetFramebufferSize(impl_->window, &fb_width, &fb_height);
  glfwGetWindowSize(impl_->window, &win_width, &win_height);
  glViewport(0, 0, fb_width, fb_height);
  glClearColor(0.08f, 0.08f, 0.09f, 1.0f);
  glClear(GL_COLOR_BUFFER_BIT);

  // Lay the views out side by side, each scaled to fit its column.
  while (impl_->textures.size() < views.size()) {
    GLuint texture = 0;
    glGenTextures(1, &texture);
    glBindTexture(GL_TEXTURE_2D, texture);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_LINEAR);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
    impl_->textures.push_back(texture);
    impl_->uploaded.emplace_back();
  }
  impl_->rects.clear();
  glUseProgram(impl_->program);
  glBindVertexArray(impl_->vao);
  const double column = views.empty() ? win_width : static_cast<double>(win_width) / views.size();
  for (size_t v = 0; v < views.size(); ++v) {
    const Image8& image = *views[v];
    if (image.empty()) continue;
    const double scale = std::min(column / image.width, static_cast<double>(win_height) / image.height);
    ViewRect rect{v * column + (column - image.width * scale) / 2,
                  (win_height - image.height * scale) / 2,
                  image.width * scale,
                  image.height * scale,
                  image.width,
                  image.height};
    impl_->rects.push_back(rect);
    glActiveTexture(GL_TEXTURE0);
    glBindTexture(GL_TEXTURE_2D, impl_->textures[v]);
    UploadView(image, new_views, impl_->uploaded[v]);
    // Window pixels (origin top-left) to clip space (origin centre, y up).
    const float x0 = static_cast<float>(rect.x0 / win_width * 2 - 1);
    const float y1 = static_cast<float>(1 - rect.y0 / win_height * 2);
    const float w = static_cast<float>(rect.width / win_width * 2),
                h = static_cast<float>(rect.height / win_height * 2);
    glUniform4f(glGetUniformLocation(impl_->program, "rect"), x0, y1 - h, w, h);
    glUniform1i(glGetUniformLocation(impl_->program, "image"), 0);
    glDrawArrays(GL_TRIANGLE_STRIP, 0, 4);
  }

  ImGui_ImplOpenGL3_NewFrame();
  ImGui_ImplGlfw_NewFrame();
  ImGui::NewFrame();
  if (draw_controls) draw_controls();
  ImGui::Render();
  ImGui_ImplOpenGL3_RenderDrawData(ImGui::GetDrawData());
  if (impl_->capture_requested) {
    impl_->capture_requested = false;
    impl_->capture = ReadBackBuffer(fb_width, fb_height);
  }
  glfwSwapBuffers(impl_->window);

  std::vector<InputEvent> events;
  events.swap(impl_->events);
  return events;
}

void LiveWindow::RequestScreenshot() { impl_->capture_requested = true; }

std::optional<Image8> LiveWindow::TakeScreenshot() {
  std::optional<Image8> shot = std::move(impl_->capture);
  impl_->capture.reset();
  return shot;
}

bool LiveWindow::ViewToWindow(int view, double x, double y, double& window_x, double& window_y) const {
  if (view < 0 || view >= static_cast<int>(impl_->rects.size())) return false;
  const ViewRect& r = impl_->rects[view];
  window_x = r.x0 + x / r.image_width * r.width;
  window_y = r.y0 + y / r.image_height * r.height;
  return true;
}

void LiveWindow::InjectMouse(InputEvent::Kind kind, double window_x, double window_y, int button) {
  impl_->HandleMouse(kind, window_x, window_y, button);
}

}  // namespace nerfar
