"""Whether an output folder's PNGs show what drawing the result's figures in this process shows (decoded
pixels, mode, size and PNG text chunks): used by the figure tests' subprocess scripts."""
import io


def folder_shows_the_drawn_figures(result, folder) -> tuple[int, bool]:
    """(number of figures drawn here, whether the folder's PNGs decode to exactly those images)."""
    n, same = folders_show_the_drawn_figures(result, {"": folder})
    return n, same[""]


def folders_show_the_drawn_figures(result, folders: dict) -> tuple[int, dict]:
    """(number of figures drawn here, {key: whether folders[key]'s PNGs decode to exactly those images}): the
    result's figures drawn once, for every folder written from that result."""
    from PIL import Image

    from mechsim.scenarios.output.figures import result_figures
    from mechsim.scenarios.output.plots import DPI

    def image(data):
        with Image.open(io.BytesIO(data)) as im:
            return im.mode, im.size, im.info, im.tobytes()

    def png(fig):
        buf = io.BytesIO()
        fig.savefig(buf, dpi=DPI, format="png")
        return buf.getvalue()
    expected = {stem: image(png(fig)) for stem, fig in result_figures(result, result.mechanism).items()}
    return len(expected), {key: {p.stem: image(p.read_bytes()) for p in folder.glob("*.png")} == expected
                           for key, folder in folders.items()}


def titles_outside(fig) -> list[str]:
    """The titles (the figure's and each axes') that reach past the figure's left or right edge when drawn: a
    title wider than the figure is cut off in the PNG."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    canvas = fig.canvas if isinstance(fig.canvas, FigureCanvasAgg) else FigureCanvasAgg(fig)
    canvas.draw()
    renderer = canvas.get_renderer()
    texts = [t for t in [fig._suptitle, *(ax.title for ax in fig.axes)] if t is not None and t.get_text()]
    width = fig.bbox.width
    return [t.get_text() for t in texts
            if t.get_window_extent(renderer).x0 < -0.5 or t.get_window_extent(renderer).x1 > width + 0.5]
